use ocp_transcription::samples::CartPole;
use ocp_transcription::*;

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

#[test]
fn explore() {
    let hy = HessianApproximation::GaussNewtonThenExact { switch_kkt: 1e-2 };
    for th in [0.5, 1.0, 1.5, 1.75, 2.0, 2.5, 3.14159] {
        for hess in [HessianApproximation::GaussNewton, hy] {
            for (name, g) in [
                ("full", Globalisation::FullStep),
                ("merit", Globalisation::merit()),
                ("soc", Globalisation::merit_soc()),
                ("filter", Globalisation::filter()),
            ] {
                let s = SqpSettings {
                    globalisation: g,
                    hessian: hess,
                    max_iterations: 100,
                    qp_recovery: true,
                    integrator: IntegratorSettings::new(IntegratorKind::Rk4, 2),
                    ..SqpSettings::default()
                };
                let mut solver =
                    SqpSolver::new(CartPole::default(), swing_up_ocp(100.0), s).unwrap();
                let x0 = [0.0, th, 0.0, 0.0];
                solver.initialize_constant(&x0, &[0.0]).unwrap();
                let st = solver.solve(&x0).unwrap();
                println!(
                    "th {th} {:?} {name}: {:?} it {} kkt {:.1e} J {:.8}",
                    hess, st.status, st.iterations, st.kkt, st.cost
                );
            }
        }
    }
}
