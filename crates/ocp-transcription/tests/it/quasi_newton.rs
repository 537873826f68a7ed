//! The Gauss–Newton-then-quasi-Newton Hessian: convergence where the model or the integrator
//! has no second derivatives.

use ocp_transcription::samples::CartPole;
use ocp_transcription::{
    Globalisation, HessianApproximation, IntegratorKind, IntegratorSettings, Ocp, SqpSettings,
    SqpSolver, SqpStats, SqpStatus,
};

fn swing_up_ocp() -> Ocp {
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

fn midpoint() -> IntegratorSettings {
    IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 2)
}

fn run(s: SqpSettings, theta: f64) -> (SqpSolver<CartPole>, SqpStats) {
    let mut solver = SqpSolver::new(CartPole::default(), swing_up_ocp(), s).unwrap();
    let x0 = [0.0, theta, 0.0, 0.0];
    solver.initialize_constant(&x0, &[0.0]).unwrap();
    let st = solver.solve(&x0).unwrap();
    (solver, st)
}

fn qn(damped_bfgs: bool) -> HessianApproximation {
    HessianApproximation::GaussNewtonThenQuasiNewton { switch_kkt: 1e-2, damped_bfgs }
}

#[test]
fn explore() {
    for theta in [std::f64::consts::PI, 2.5, 2.0, 1.75, 1.5, 1.0] {
        for (name, h) in [
            ("gn", HessianApproximation::GaussNewton),
            ("sr1", qn(false)),
            ("bfgs", qn(true)),
        ] {
            for g in [Globalisation::merit_soc(), Globalisation::filter()] {
                let s = SqpSettings {
                    hessian: h,
                    globalisation: g,
                    max_iterations: 200,
                    ..SqpSettings::converge(midpoint())
                };
                let (_, st) = run(s, theta);
                println!(
                    "theta {theta:.3} {name} {}: {:?} it {} kkt {:.1e} J {:.10} upd {}",
                    if matches!(g, Globalisation::Filter { .. }) { "filter" } else { "merit" },
                    st.status,
                    st.iterations,
                    st.kkt,
                    st.cost,
                    st.quasi_newton_updates
                );
            }
        }
    }
}
