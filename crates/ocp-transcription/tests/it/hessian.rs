//! The Gauss–Newton-then-exact Hessian: convergence where full steps do not, infeasible QPs,
//! superlinear convergence near the solution, fallback starts, settings validation.

use ocp_transcription::samples::{CartPole, Fragile};
use ocp_transcription::{
    Globalisation, HessianApproximation, IntegratorKind, IntegratorSettings, Ocp, SqpSettings,
    SqpSolver, SqpStats, SqpStatus, Start,
};

const HYBRID: HessianApproximation =
    HessianApproximation::GaussNewtonThenExact { switch_kkt: 1e-2 };

/// The cart-pole swing-up problem of the Hessian tests (also used by the quasi-Newton tests).
pub(crate) fn swing_up_ocp() -> Ocp {
    let mut ocp = Ocp::new(4, 1, 1.5, 30).unwrap();
    ocp.q =
        nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![10.0, 10.0, 0.1, 0.1]));
    ocp.r = nalgebra::DMatrix::identity(1, 1) * 1e-3;
    ocp.terminal = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![
        100.0, 100.0, 10.0, 10.0,
    ]));
    ocp.u_min[0] = -25.0;
    ocp.u_max[0] = 25.0;
    ocp
}

fn settings(hessian: HessianApproximation, g: Globalisation) -> SqpSettings {
    SqpSettings {
        hessian,
        globalisation: g,
        max_iterations: 100,
        qp_recovery: true,
        integrator: IntegratorSettings::new(IntegratorKind::Rk4, 2),
        ..SqpSettings::default()
    }
}

fn run(ocp: &Ocp, s: SqpSettings, theta: f64) -> (SqpSolver<CartPole>, SqpStats) {
    let mut solver = SqpSolver::new(CartPole::default(), ocp.clone(), s).unwrap();
    let x0 = [0.0, theta, 0.0, 0.0];
    solver.initialize_constant(&x0, &[0.0]).unwrap();
    let st = solver.solve(&x0).unwrap();
    (solver, st)
}

/// Swing-up from 1.5 rad: full steps oscillate without converging (KKT ≈ 1.4 after 100
/// iterations, measured), every line search converges to the same point with the
/// Gauss–Newton-then-exact Hessian.
#[test]
fn every_globalisation_converges_where_full_steps_do_not() {
    let ocp = swing_up_ocp();
    let tol = |s: SqpSettings| SqpSettings { kkt_tolerance: 1e-6, ..s };
    let (_, full) = run(&ocp, tol(settings(HYBRID, Globalisation::FullStep)), 1.5);
    println!("full: {:?} {} {:.2e}", full.status, full.iterations, full.kkt);
    assert_eq!(full.status, SqpStatus::MaxIterations);
    assert!(full.kkt > 0.1, "full steps: KKT {}", full.kkt);
    let mut costs = Vec::new();
    for g in [Globalisation::merit(), Globalisation::merit_soc(), Globalisation::filter()] {
        let (solver, st) = run(&ocp, tol(settings(HYBRID, g)), 1.5);
        println!("{g:?}: {:?} {} {:.2e} {}", st.status, st.iterations, st.kkt, st.cost);
        assert_eq!(st.status, SqpStatus::Solved, "{g:?}");
        assert!(st.kkt <= 1e-6, "{g:?}");
        assert!(solver.controls().iter().all(|u| u[0].abs() <= 25.0));
        costs.push(st.cost);
    }
    for c in &costs {
        assert!((c - costs[0]).abs() <= 1e-6 * costs[0], "{costs:?}");
    }
}

/// An infeasible QP (the cart cannot reach p ≥ 10) ends in `QpInfeasible` under every
/// globalisation with the Gauss–Newton-then-exact and the projected Hessian.
#[test]
fn infeasible_qp_ends_in_its_status() {
    let mut bad = swing_up_ocp();
    bad.x_min[0] = 10.0;
    for h in [HYBRID, HessianApproximation::ExactProjected] {
        for g in [
            Globalisation::FullStep,
            Globalisation::merit(),
            Globalisation::merit_soc(),
            Globalisation::filter(),
        ] {
            let (_, st) = run(&bad, settings(h, g), std::f64::consts::PI);
            assert_eq!(st.status, SqpStatus::QpInfeasible, "{h:?} {g:?}");
            assert!(!st.status.has_iterate());
        }
    }
}

/// Near the solution the exact Hessian converges superlinearly where Gauss–Newton converges
/// linearly: from the hanging position, the KKT ratio `e⁺/e` of the last iterations.
#[test]
fn superlinear_near_the_solution() {
    let ocp = swing_up_ocp();
    let ratios = |h| {
        let (solver, st) = run(&ocp, settings(h, Globalisation::merit_soc()), std::f64::consts::PI);
        assert_eq!(st.status, SqpStatus::Solved, "{h:?}");
        let mut e: Vec<f64> = solver.log().iter().map(|l| l.kkt).collect();
        e.push(st.kkt);
        println!("{h:?}: {:?}", e);
        let tail: Vec<f64> = e.windows(2).map(|w| w[1] / w[0]).collect();
        (tail[tail.len() - 1].min(tail[tail.len() - 2]), st.iterations)
    };
    let (gn, it_gn) = ratios(HessianApproximation::GaussNewton);
    let (hy, it_hy) = ratios(HYBRID);
    println!("GN {gn} {it_gn}, hybrid {hy} {it_hy}");
    assert!(hy < 0.05, "hybrid: best of the last two KKT ratios {hy}");
    assert!(gn > 0.1, "Gauss–Newton: {gn}");
    assert!(it_hy < it_gn, "{it_hy} vs {it_gn}");
}

/// Nodes where the dynamics are not finite (the fragile cart-pole beyond |p| = 0.5): the
/// plain solve ends in `NonFiniteDynamics` at iteration 0; the fallback starts roll the
/// controls out from `x0` and iterate from there.
#[test]
fn fallback_start_from_a_rollout() {
    let s = SqpSettings {
        max_iterations: 3,
        ..settings(HessianApproximation::GaussNewton, Globalisation::merit_soc())
    };
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let mut solver = SqpSolver::new(Fragile::default(), swing_up_ocp(), s).unwrap();
    solver.initialize_constant(&[1.0, 3.0, 0.0, 0.0], &[0.0]).unwrap();
    let st = solver.solve(&x0).unwrap();
    assert_eq!((st.status, st.iterations), (SqpStatus::NonFiniteDynamics, 0));
    let (st, start) = solver.solve_with_fallback_starts(&x0).unwrap();
    assert_eq!(start, Start::RolledOutControls);
    assert!(st.iterations > 0, "{st:?}");
    assert_eq!(solver.states()[0].as_slice(), &x0);
}

#[test]
fn switch_threshold_is_validated() {
    for bad in [0.0, -1.0, f64::NAN] {
        let s = SqpSettings {
            hessian: HessianApproximation::GaussNewtonThenExact { switch_kkt: bad },
            ..SqpSettings::default()
        };
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("switch_kkt"), "{e}");
    }
    SqpSettings::converge(IntegratorSettings::default()).validate().unwrap();
    SqpSettings::converge_filter(IntegratorSettings::default()).validate().unwrap();
}

/// A converged solve takes the interval maps to round-off: `SqpSettings::converge` tightens a
/// real-time Newton tolerance to the default and keeps a tighter one.
#[test]
fn converge_tightens_a_loose_newton_tolerance() {
    let loose = IntegratorSettings {
        newton_tolerance: 1e-8,
        ..IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 4)
    };
    let default = IntegratorSettings::default().newton_tolerance;
    assert_eq!(SqpSettings::converge(loose.clone()).integrator.newton_tolerance, default);
    assert_eq!(SqpSettings::converge_filter(loose).integrator.newton_tolerance, default);
    let tight = IntegratorSettings { newton_tolerance: 1e-15, ..IntegratorSettings::default() };
    assert_eq!(SqpSettings::converge(tight).integrator.newton_tolerance, 1e-15);
}
