//! SQP: the LQR identity, the cart-pole swing-up (cold start, exact Hessian, active bounds),
//! and the failure statuses.

use nalgebra::{DMatrix, DVector};
use ocp_transcription::samples::{self, CartPole, Fragile, LinearModel};
use ocp_transcription::{
    Dynamics, Globalisation, HessianApproximation, IntegratorKind, IntegratorSettings, Ocp, QpForm,
    SqpMode, SqpSettings, SqpSolver, SqpStatus,
};

pub(crate) fn lqr_problem() -> (LinearModel, Ocp) {
    let model = LinearModel::spring_chain(3, 2);
    let mut ocp = Ocp::new(6, 2, 3.0, 15).unwrap();
    ocp.r = DMatrix::identity(2, 2) * 0.5;
    ocp.terminal = DMatrix::identity(6, 6) * 2.0;
    (model, ocp)
}

#[test]
fn lq_problem_equals_riccati_in_one_iteration() {
    let (model, ocp) = lqr_problem();
    let x0 = DVector::from_vec(vec![0.5, -0.3, 0.2, 0.0, 0.4, -0.1]);
    for form in [QpForm::Auto, QpForm::CondensedClarabel, QpForm::SparseClarabel] {
        for mode in [SqpMode::Sqp, SqpMode::LinearQuadratic] {
            let settings = SqpSettings { qp_form: form, mode, ..SqpSettings::default() };
            let (xs, us) = samples::riccati_plan(&model, &ocp, &settings.integrator, &x0).unwrap();
            let mut solver = SqpSolver::new(&model, ocp.clone(), settings).unwrap();
            let stats = solver.solve(x0.as_slice()).unwrap();
            assert_eq!(stats.status, SqpStatus::Solved, "{form:?} {mode:?}");
            assert_eq!(stats.iterations, 1, "{form:?} {mode:?}: one QP");
            let mut err = 0.0_f64;
            for k in 0..ocp.intervals {
                err = err.max((&solver.controls()[k] - &us[k]).amax());
                err = err.max((&solver.states()[k + 1] - &xs[k + 1]).amax());
            }
            // both are exact solutions of the same linear system of optimality conditions
            // (condition number ~1e3); the QP tolerance is 1e-11
            assert!(err < 1e-8, "{form:?} {mode:?}: deviation from Riccati {err:e}");
        }
    }
}

/// Swing-up from hanging (θ = π) to upright in 1.5 s with |F| ≤ 25 N.
fn swing_up_ocp() -> Ocp {
    let mut ocp = Ocp::new(4, 1, 1.5, 30).unwrap();
    ocp.q = DMatrix::from_diagonal(&DVector::from_vec(vec![10.0, 10.0, 0.1, 0.1]));
    ocp.r = DMatrix::identity(1, 1) * 1e-3;
    ocp.terminal = DMatrix::from_diagonal(&DVector::from_vec(vec![100.0, 100.0, 10.0, 10.0]));
    ocp.u_min[0] = -25.0;
    ocp.u_max[0] = 25.0;
    ocp
}

fn swing_up(
    hessian: HessianApproximation,
    form: QpForm,
) -> (SqpSolver<CartPole>, ocp_transcription::SqpStats) {
    let model = CartPole::default();
    let ocp = swing_up_ocp();
    let settings = SqpSettings {
        hessian,
        qp_form: form,
        max_iterations: 100,
        integrator: IntegratorSettings::new(IntegratorKind::Rk4, 2),
        ..SqpSettings::default()
    };
    let mut solver = SqpSolver::new(model, ocp, settings).unwrap();
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    solver.initialize_constant(&x0, &[0.0]).unwrap();
    let stats = solver.solve(&x0).unwrap();
    (solver, stats)
}

#[test]
fn cartpole_swing_up_converges_with_active_bounds() {
    for (hessian, form) in [
        (HessianApproximation::GaussNewton, QpForm::Auto),
        (HessianApproximation::Exact, QpForm::Auto),
        (HessianApproximation::GaussNewton, QpForm::SparseClarabel),
    ] {
        let (solver, stats) = swing_up(hessian, form);
        for l in solver.log() {
            println!(
                "{hessian:?} {form:?} it {:2} J {:.6e} kkt {:.3e} viol {:.3e} |dw| {:.3e} t {:.3} qp {}",
                l.iteration, l.cost, l.kkt, l.constraint_violation, l.step_norm, l.step_length, l.qp_iterations
            );
        }
        println!("{stats:?}");
        assert_eq!(stats.status, SqpStatus::Solved, "{hessian:?} {form:?}");
        assert!(stats.kkt <= 1e-8);
        // the swing-up saturates the force
        let active = solver.controls().iter().filter(|u| (u[0].abs() - 25.0).abs() < 1e-9).count();
        assert!(active >= 2, "{hessian:?}: {active} active bounds");
        // the pole ends upright
        assert!(solver.states()[30][1].abs() < 0.2, "final angle {}", solver.states()[30][1]);
        if hessian == HessianApproximation::Exact {
            // quadratic convergence: the last two KKT reductions satisfy e⁺ ≤ 10 e²
            let mut e: Vec<f64> = solver.log().iter().map(|l| l.kkt).collect();
            e.push(stats.kkt);
            let m = e.len();
            for w in e[m - 3..].windows(2) {
                assert!(w[1] <= 10.0 * w[0] * w[0], "not quadratic: {} -> {}", w[0], w[1]);
            }
            assert!(stats.iterations < 45, "exact Hessian took {} iterations", stats.iterations);
        }
    }
}

#[test]
fn failures_end_in_a_status() {
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let ocp = swing_up_ocp();
    // NaN from the dynamics at the initial guess (p = 0.6 is outside the model's domain)
    let settings = SqpSettings { globalisation: Globalisation::FullStep, ..SqpSettings::default() };
    let mut solver =
        SqpSolver::new(Fragile(CartPole::default()), ocp.clone(), settings.clone()).unwrap();
    solver.initialize_constant(&[0.6, 3.0, 0.0, 0.0], &[0.0]).unwrap();
    let stats = solver.solve(&x0).unwrap();
    assert_eq!(stats.status, SqpStatus::NonFiniteDynamics);
    assert!(!stats.status.has_iterate());
    assert!(solver.controls().iter().all(|u| u[0].is_finite()));
    // iteration limit
    let settings = SqpSettings { max_iterations: 3, ..SqpSettings::default() };
    let mut solver = SqpSolver::new(CartPole::default(), ocp.clone(), settings).unwrap();
    solver.initialize_constant(&x0, &[0.0]).unwrap();
    let stats = solver.solve(&x0).unwrap();
    assert_eq!(stats.status, SqpStatus::MaxIterations);
    assert_eq!(stats.iterations, 3);
    assert!(stats.kkt > 1e-8);
    // infeasible QP: the cart must be at p ≥ 10 after the first interval (|F| ≤ 25)
    let mut bad = ocp.clone();
    bad.x_min[0] = 10.0;
    for form in [QpForm::Auto, QpForm::CondensedClarabel, QpForm::SparseClarabel] {
        let settings = SqpSettings { qp_form: form, ..SqpSettings::default() };
        let mut solver = SqpSolver::new(CartPole::default(), bad.clone(), settings).unwrap();
        solver.initialize_constant(&x0, &[0.0]).unwrap();
        let stats = solver.solve(&x0).unwrap();
        assert_eq!(stats.status, SqpStatus::QpInfeasible, "{form:?}");
    }
    // bad input is an Err, not a status
    assert!(solver.solve(&[0.0; 3]).is_err());
    assert!(solver.solve(&[f64::NAN, 0.0, 0.0, 0.0]).is_err());
}

#[test]
fn bad_settings_are_rejected() {
    let ocp = Ocp::new(4, 1, 1.0, 10).unwrap();
    let bad = [
        SqpSettings { max_iterations: 0, ..SqpSettings::default() },
        SqpSettings {
            globalisation: Globalisation::FixedRelaxation { alpha: 1.5 },
            ..SqpSettings::default()
        },
        SqpSettings { levenberg_marquardt: -1.0, ..SqpSettings::default() },
        SqpSettings {
            integrator: IntegratorSettings::new(IntegratorKind::Rk4, 0),
            ..SqpSettings::default()
        },
        SqpSettings {
            hessian: HessianApproximation::Exact,
            integrator: IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 2),
            ..SqpSettings::default()
        },
        SqpSettings {
            hessian: HessianApproximation::Exact,
            qp_form: QpForm::SparseClarabel,
            ..SqpSettings::default()
        },
    ];
    for s in bad {
        assert!(SqpSolver::new(CartPole::default(), ocp.clone(), s.clone()).is_err(), "{s:?}");
    }
    let mut wrong = ocp.clone();
    wrong.u_min[0] = 1.0;
    wrong.u_max[0] = -1.0;
    assert!(SqpSolver::new(CartPole::default(), wrong, SqpSettings::default()).is_err());
    assert!(SqpSolver::new(
        CartPole::default(),
        Ocp::new(3, 1, 1.0, 10).unwrap(),
        SqpSettings::default()
    )
    .is_err());
}

/// Warm start by shifting and real-time iterations track the swing-up solution.
#[test]
fn shift_and_real_time_iteration() {
    let (mut solver, stats) = swing_up(HessianApproximation::GaussNewton, QpForm::Auto);
    assert_eq!(stats.status, SqpStatus::Solved);
    // re-solving from the converged point takes no QP
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let again = solver.solve(&x0).unwrap();
    assert_eq!((again.status, again.iterations), (SqpStatus::Solved, 0));
    // shift by one interval and solve from the predicted state: far fewer iterations than cold
    let x1: Vec<f64> = solver.states()[1].iter().copied().collect();
    solver.shift(1);
    let warm = solver.solve(&x1).unwrap();
    assert_eq!(warm.status, SqpStatus::Solved);
    assert!(
        warm.iterations < stats.iterations / 2,
        "warm {} vs cold {}",
        warm.iterations,
        stats.iterations
    );
    // fractional shift keeps the controls within bounds and finite
    solver.shift_time(0.03).unwrap();
    assert!(solver.controls().iter().all(|u| u[0].abs() <= 25.0));
}

#[test]
fn real_time_iteration_does_one_step() {
    let model = CartPole::default();
    let mut ocp = Ocp::new(4, 1, 1.5, 30).unwrap();
    ocp.u_min[0] = -25.0;
    ocp.u_max[0] = 25.0;
    let settings = SqpSettings { mode: SqpMode::RealTimeIteration, ..SqpSettings::default() };
    let mut solver = SqpSolver::new(model, ocp, settings).unwrap();
    let x0 = [0.0, 0.3, 0.0, 0.0];
    solver.initialize_constant(&x0, &[0.0]).unwrap();
    let mut kkt = Vec::new();
    for _ in 0..8 {
        let s = solver.solve(&x0).unwrap();
        assert_eq!((s.status, s.iterations), (SqpStatus::RealTimeIteration, 1));
        kkt.push(s.kkt);
    }
    // repeated RTI steps at a fixed x0 converge (the KKT residual is measured before each step)
    assert!(kkt[7] < 1e-3 * kkt[0], "{kkt:?}");
}

/// Integrating the intervals on the thread pool gives bit-identical iterates.
#[test]
fn parallel_intervals_match_sequential() {
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let mut results = Vec::new();
    for parallel in [false, true] {
        let settings = SqpSettings {
            parallel_intervals: parallel,
            max_iterations: 100,
            integrator: IntegratorSettings::new(IntegratorKind::Rk4, 2),
            ..SqpSettings::default()
        };
        let mut solver = SqpSolver::new(CartPole::default(), swing_up_ocp(), settings).unwrap();
        solver.initialize_constant(&x0, &[0.0]).unwrap();
        let stats = solver.solve(&x0).unwrap();
        assert_eq!(stats.status, SqpStatus::Solved);
        results.push((stats.iterations, solver.controls().to_vec()));
    }
    assert_eq!(results[0], results[1]);
}

/// The linear–quadratic mode on the cart-pole at the upright equilibrium equals the SQP on the
/// linearised ODE: at an equilibrium every RK4 stage sits at the reference, so the
/// linearisation of the discrete map is the discrete map of the linearisation.
#[test]
fn linear_quadratic_mode_equals_sqp_on_the_linearised_model() {
    let cp = CartPole::default();
    let (mut fx, mut fu) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
    cp.jacobians(&[0.0; 4], &[0.0], &mut fx, &mut fu);
    let lin = LinearModel::new(fx, fu).unwrap();
    let mut ocp = Ocp::new(4, 1, 2.0, 20).unwrap();
    ocp.u_min[0] = -2.0;
    ocp.u_max[0] = 2.0;
    let x0 = [0.1, 0.2, 0.0, -0.1];
    let lq = SqpSettings { mode: SqpMode::LinearQuadratic, ..SqpSettings::default() };
    let mut a = SqpSolver::new(CartPole::default(), ocp.clone(), lq).unwrap();
    let sa = a.solve(&x0).unwrap();
    let mut b = SqpSolver::new(lin, ocp, SqpSettings::default()).unwrap();
    let sb = b.solve(&x0).unwrap();
    assert_eq!((sa.status, sb.status), (SqpStatus::Solved, SqpStatus::Solved));
    assert_eq!(sa.iterations, 1, "one QP per sample");
    // the force saturates at the start: bounds are active
    assert!((a.controls()[0][0].abs() - 2.0).abs() < 1e-9);
    for k in 0..20 {
        // same QP, same solver: equal to the interior-point tolerance
        assert!((&a.controls()[k] - &b.controls()[k]).amax() < 1e-9, "{k}");
    }
}

/// Shifting by one interval's time equals shifting by one interval.
#[test]
fn shift_time_of_one_interval_equals_shift() {
    let (mut a, _) = swing_up(HessianApproximation::GaussNewton, QpForm::Auto);
    let mut b = SqpSolver::new(CartPole::default(), swing_up_ocp(), a.settings().clone()).unwrap();
    b.states_mut().clone_from_slice(a.states());
    b.controls_mut().clone_from_slice(a.controls());
    a.shift(1);
    b.shift_time(1.5 / 30.0).unwrap();
    for k in 0..=30 {
        assert!((&a.states()[k] - &b.states()[k]).amax() < 1e-12);
    }
    for k in 0..30 {
        assert_eq!(a.controls()[k], b.controls()[k]);
    }
}

/// `roll_out(x0, k)`: the first `k` nodes are the controls integrated from `x0` (the same
/// bits as the full rollout's first `k`), the later nodes and the multipliers stay.
#[test]
fn roll_out_resimulates_only_the_head() {
    let (model, ocp) = lqr_problem();
    let n = ocp.intervals;
    let x0 = DVector::from_vec(vec![0.5, -0.3, 0.2, 0.0, 0.4, -0.1]);
    let mut solver = SqpSolver::new(&model, ocp, SqpSettings::default()).unwrap();
    solver.solve(x0.as_slice()).unwrap();
    let (plan, lam) = (solver.states().to_vec(), solver.multipliers().to_vec());
    let x1 = DVector::from_vec(vec![0.6, -0.2, 0.1, 0.3, 0.4, 0.0]);
    let mut full = SqpSolver::new(&model, solver.ocp().clone(), SqpSettings::default()).unwrap();
    full.controls_mut().clone_from_slice(solver.controls());
    full.initialize_by_rollout(x1.as_slice()).unwrap();
    solver.roll_out(x1.as_slice(), 3).unwrap();
    for k in 0..=n {
        let want = if k <= 3 { &full.states()[k] } else { &plan[k] };
        assert_eq!(&solver.states()[k], want, "node {k}");
    }
    assert_eq!(solver.multipliers(), &lam[..], "multipliers kept");
    assert!(lam.iter().any(|l| l.amax() > 0.0), "the solve left non-zero multipliers");
    // more intervals than the horizon: the whole plan, like the full rollout
    solver.roll_out(x1.as_slice(), n + 5).unwrap();
    assert_eq!(solver.states(), full.states());
    assert!(solver.roll_out(&[0.0; 2], 1).is_err(), "wrong x0 length");
}
