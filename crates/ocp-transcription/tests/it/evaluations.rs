//! The work counts ([`Evaluations`]) against the model calls actually made.

use crate::hessian::swing_up_ocp;
use nalgebra::DMatrix;
use ocp_transcription::samples::CartPole;
use ocp_transcription::{
    Dynamics, Evaluations, Integrator, IntegratorKind, IntegratorSettings, SqpSettings, SqpSolver,
};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A model that counts its own calls.
#[derive(Default)]
struct Counted {
    inner: CartPole,
    rhs: AtomicUsize,
    jacobians: AtomicUsize,
    hessians: AtomicUsize,
}

impl Counted {
    fn counts(&self) -> (usize, usize, usize) {
        let r = |c: &AtomicUsize| c.load(Ordering::Relaxed);
        (r(&self.rhs), r(&self.jacobians), r(&self.hessians))
    }
}

fn bump(c: &AtomicUsize) {
    c.fetch_add(1, Ordering::Relaxed);
}

impl Dynamics for Counted {
    fn nx(&self) -> usize {
        self.inner.nx()
    }
    fn nu(&self) -> usize {
        self.inner.nu()
    }
    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
        bump(&self.rhs);
        self.inner.rhs(x, u, xdot)
    }
    fn jacobians(&self, x: &[f64], u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        bump(&self.jacobians);
        self.inner.jacobians(x, u, fx, fu)
    }
    fn rhs_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        xdot: &mut [f64],
        fx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) {
        bump(&self.jacobians);
        self.inner.rhs_and_jacobians(x, u, xdot, fx, fu)
    }
    fn has_second_order(&self) -> bool {
        self.inner.has_second_order()
    }
    fn weighted_hessian(&self, x: &[f64], u: &[f64], w: &[f64], out: &mut DMatrix<f64>) {
        bump(&self.hessians);
        self.inner.weighted_hessian(x, u, w, out)
    }
}

fn midpoint(simplified_newton: bool) -> IntegratorSettings {
    IntegratorSettings {
        simplified_newton,
        ..IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 3)
    }
}

/// Every integration path counts exactly the model calls it makes; RK4 makes four stages
/// per substep.
#[test]
fn integrator_counts_match_the_model_calls() {
    let (x0, u) = ([0.1, 2.5, 0.3, -0.4], [1.5]);
    for settings in
        [IntegratorSettings::new(IntegratorKind::Rk4, 3), midpoint(true), midpoint(false)]
    {
        let model = Counted::default();
        let mut int = Integrator::new(&model, &settings, 0.1).unwrap();
        let mut x1 = vec![0.0; 4];
        let (mut a, mut b) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
        int.integrate(&model, &x0, &u, &mut x1).unwrap();
        int.integrate_with_sensitivities(&model, &x0, &u, &mut x1, &mut a, &mut b).unwrap();
        let e = int.evaluations();
        assert_eq!((e.rhs, e.jacobians, e.hessians), model.counts(), "{settings:?}");
        if settings.kind == IntegratorKind::Rk4 {
            // 3 substeps × 4 stages, without and then with sensitivities
            assert_eq!(e, Evaluations { rhs: 12, jacobians: 12, ..Evaluations::default() });
        } else {
            // a factorisation at least per substep of the sensitivity pass
            assert!(e.factorisations >= 3 && e.jacobians >= 3, "{e:?}");
        }
    }
}

/// A solve's counts are the work between two readings of the solver's, and they match the
/// model calls (the exact Hessian's second derivatives included).
#[test]
fn solver_counts_match_the_model_calls() {
    for settings in [
        SqpSettings::converge(IntegratorSettings::new(IntegratorKind::Rk4, 2)),
        SqpSettings { max_iterations: 5, ..SqpSettings::converge_quasi_newton(midpoint(true)) },
    ] {
        let model = Counted::default();
        let mut solver = SqpSolver::new(&model, swing_up_ocp(), settings).unwrap();
        let x0 = [0.0, 0.5, 0.0, 0.0];
        solver.initialize_constant(&x0, &[0.0]).unwrap();
        let before = solver.evaluations();
        let stats = solver.solve(&x0).unwrap();
        let total = solver.evaluations();
        assert_eq!(stats.evaluations, total - before);
        assert_eq!((total.rhs, total.jacobians, total.hessians), model.counts());
        assert!(stats.iterations > 0 && stats.evaluations.rhs > 0, "{stats:?}");
        assert!(stats.evaluations.jacobians > 0, "{stats:?}");
    }
}

/// The line-search trial count: at least one trial pass per step of a line search, none with
/// full steps; a running total over the solver's solves.
#[test]
fn line_search_trials_count_the_trial_passes() {
    let full = SqpSettings {
        globalisation: ocp_transcription::Globalisation::FullStep,
        ..SqpSettings::converge(IntegratorSettings::new(IntegratorKind::Rk4, 2))
    };
    for (settings, searched) in [
        (SqpSettings::converge(IntegratorSettings::new(IntegratorKind::Rk4, 2)), true),
        (full, false),
    ] {
        let model = Counted::default();
        let mut solver = SqpSolver::new(&model, swing_up_ocp(), settings).unwrap();
        let x0 = [0.0, 0.5, 0.0, 0.0];
        solver.initialize_constant(&x0, &[0.0]).unwrap();
        assert_eq!(solver.line_search_trials(), 0);
        let stats = solver.solve(&x0).unwrap();
        let first = solver.line_search_trials();
        assert!(stats.iterations > 0, "{stats:?}");
        if searched {
            assert!(first >= stats.iterations, "{first} trials, {stats:?}");
            // a second solve from the same start adds its own trials to the running total
            solver.initialize_constant(&x0, &[0.0]).unwrap();
            let again = solver.solve(&x0).unwrap();
            assert!(again.iterations > 0, "{again:?}");
            assert_eq!(solver.line_search_trials(), 2 * first, "the same solve again");
        } else {
            assert_eq!(first, 0, "{stats:?}");
        }
    }
}
