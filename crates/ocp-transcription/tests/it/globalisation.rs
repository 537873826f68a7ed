//! Globalisation: problems where full Gauss–Newton steps fail and the line searches converge,
//! infeasible QPs ending in their status, and bit-identical parallel trials.

use ocp_transcription::samples::CartPole;
use ocp_transcription::{
    Globalisation, IntegratorKind, IntegratorSettings, Ocp, SqpSettings, SqpSolver, SqpStats,
    SqpStatus,
};

fn swing_up_ocp(terminal: f64) -> Ocp {
    let mut ocp = Ocp::new(4, 1, 1.5, 30).unwrap();
    ocp.q =
        nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![10.0, 10.0, 0.1, 0.1]));
    ocp.r = nalgebra::DMatrix::identity(1, 1) * 1e-3;
    ocp.terminal = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![
        terminal,
        terminal,
        0.1 * terminal,
        0.1 * terminal,
    ]));
    ocp.u_min[0] = -25.0;
    ocp.u_max[0] = 25.0;
    ocp
}

fn run(ocp: &Ocp, settings: SqpSettings, x0: &[f64]) -> (SqpSolver<CartPole>, SqpStats) {
    let mut solver = SqpSolver::new(CartPole::default(), ocp.clone(), settings).unwrap();
    solver.initialize_constant(x0, &[0.0]).unwrap();
    let stats = solver.solve(x0).unwrap();
    (solver, stats)
}

fn settings(g: Globalisation) -> SqpSettings {
    SqpSettings {
        globalisation: g,
        max_iterations: 100,
        integrator: IntegratorSettings::new(IntegratorKind::Rk4, 2),
        ..SqpSettings::default()
    }
}

/// Cart-pole swing-up from 1.75 rad (RK4 × 2, Nc = 30): the merit line search with the
/// growing penalty stops at its minimum step just above the tolerance, while the merit search
/// with the multiplier-following penalty and the second-order correction, and the filter,
/// converge to the same optimum (measured: merit `LineSearchFailed` at KKT 1.1e-8 after 24
/// iterations; corrected merit 19, filter 13 iterations, J = 32.03749).
#[test]
fn corrected_merit_and_filter_converge_where_the_merit_search_stops() {
    let x0 = [0.0, 1.75, 0.0, 0.0];
    let ocp = swing_up_ocp(100.0);
    let (_, merit) = run(&ocp, settings(Globalisation::merit()), &x0);
    assert_eq!(merit.status, SqpStatus::LineSearchFailed);
    assert!(!merit.status.has_iterate());
    let (_, full) = run(&ocp, settings(Globalisation::FullStep), &x0);
    assert_eq!(full.status, SqpStatus::Solved);
    for g in [Globalisation::merit_soc(), Globalisation::filter()] {
        let (solver, st) = run(&ocp, settings(g), &x0);
        assert_eq!(st.status, SqpStatus::Solved, "{g:?}");
        assert!(st.kkt <= 1e-8, "{g:?}: {}", st.kkt);
        assert!(st.iterations <= 30, "{g:?}: {} iterations", st.iterations);
        assert!(
            (st.cost - full.cost).abs() <= 1e-9 * full.cost,
            "{g:?}: {} vs {}",
            st.cost,
            full.cost
        );
        assert!(solver.controls().iter().all(|u| u[0].abs() <= 25.0));
    }
}

/// From the hanging position both new line searches reach the full-step optimum, the filter
/// in as many iterations as full steps (28), the corrected merit in 29 against the plain
/// merit's 53 (the merit rejects full steps the others accept).
#[test]
fn filter_keeps_the_full_steps_that_converge() {
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let ocp = swing_up_ocp(100.0);
    let (_, full) = run(&ocp, settings(Globalisation::FullStep), &x0);
    let (_, merit) = run(&ocp, settings(Globalisation::merit()), &x0);
    assert_eq!(full.status, SqpStatus::Solved);
    assert_eq!(merit.status, SqpStatus::Solved);
    for g in [Globalisation::merit_soc(), Globalisation::filter()] {
        let (_, st) = run(&ocp, settings(g), &x0);
        assert_eq!(st.status, SqpStatus::Solved, "{g:?}");
        assert!((st.cost - full.cost).abs() <= 1e-9 * full.cost, "{g:?}");
        assert!(
            st.iterations < merit.iterations,
            "{g:?}: {} vs {}",
            st.iterations,
            merit.iterations
        );
    }
}

/// An infeasible QP (the cart cannot reach p ≥ 10 within one interval) ends in
/// `QpInfeasible` with every globalisation, with QP recovery on: recovery regularises failed
/// QPs, it does not hide infeasibility.
#[test]
fn infeasible_qp_ends_in_its_status_with_every_globalisation() {
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let mut bad = swing_up_ocp(100.0);
    bad.x_min[0] = 10.0;
    for g in [Globalisation::merit(), Globalisation::merit_soc(), Globalisation::filter()] {
        let s = SqpSettings { qp_recovery: true, ..settings(g) };
        let (_, st) = run(&bad, s, &x0);
        assert_eq!(st.status, SqpStatus::QpInfeasible, "{g:?}");
        assert!(!st.status.has_iterate());
        assert_eq!(st.qp_recoveries, 0);
    }
}

/// Line-search trials integrated on the thread pool give bit-identical iterates.
#[test]
fn parallel_trials_match_sequential() {
    let x0 = [0.0, 1.75, 0.0, 0.0];
    let ocp = swing_up_ocp(100.0);
    for g in [Globalisation::merit(), Globalisation::filter()] {
        let mut results = Vec::new();
        for parallel in [false, true] {
            let s = SqpSettings { parallel_intervals: parallel, ..settings(g) };
            let (solver, st) = run(&ocp, s, &x0);
            results.push((st.status, st.iterations, st.cost.to_bits(), solver.controls().to_vec()));
        }
        assert_eq!(results[0], results[1], "{g:?}");
    }
}

/// `SqpSettings::converge` is valid and iterates to 1e-8.
#[test]
fn converge_settings() {
    let s = SqpSettings::converge(IntegratorSettings::new(IntegratorKind::Rk4, 2));
    s.validate().unwrap();
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let (_, st) = run(&swing_up_ocp(100.0), s, &x0);
    assert_eq!(st.status, SqpStatus::Solved);
    assert!(st.kkt <= 1e-8);
}
