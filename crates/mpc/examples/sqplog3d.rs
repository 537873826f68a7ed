//! Diagnostic (issue 6, 3D): the SQP iteration log of the NMPC's first attempt at one state
//! of a recorded closed loop (`timeseries.csv` of `flexmpc mpc`, columns `q0…`), warm-started
//! from the linear MPC plan as at a first sample, with a larger iteration limit.
//! `sqplog3d <timeseries.csv> <t> [max_iterations]`.
use mpc::{RomDynamics, Scenario, Setup};
use nalgebra::DVector;
use ocp_transcription::{
    Globalisation, HessianApproximation, IntegratorKind, IntegratorSettings, Ocp, SqpMode,
    SqpSettings, SqpSolver,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let path = a.get(1).ok_or("timeseries.csv path")?;
    let t: f64 = a.get(2).map_or(Ok(5.0), |s| s.parse())?;
    let iters: usize = a.get(3).map_or(Ok(40), |s| s.parse())?;
    let text = std::fs::read_to_string(path)?;
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().ok_or("empty csv")?.split(',').collect();
    let qcols: Vec<usize> =
        (0..).map_while(|i| head.iter().position(|h| *h == format!("q{i}"))).collect();
    let row = lines
        .map(|l| l.split(',').map(|v| v.parse::<f64>()).collect::<Result<Vec<_>, _>>())
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .min_by(|x, y| (x[0] - t).abs().total_cmp(&(y[0] - t).abs()))
        .ok_or("no rows")?;
    let x0: Vec<f64> = qcols.iter().map(|&c| row[c]).collect();
    let sc = Scenario::paper_3d(50)?;
    let setup = Setup::new(&sc)?;
    let model = RomDynamics::new(&setup.rom)?;
    let nu = sc.inputs.len();
    let mut ocp = Ocp::new(x0.len(), nu, sc.mpc.horizon, sc.mpc.intervals)?;
    ocp.q = setup.weights.q.clone();
    ocp.r = setup.weights.r.clone();
    ocp.x_ref = setup.weights.x_ref.clone();
    ocp.u_ref = DVector::zeros(nu);
    ocp.u_min = DVector::from_element(nu, -sc.mpc.u_max);
    ocp.u_max = DVector::from_element(nu, sc.mpc.u_max);
    let base = SqpSettings {
        hessian: HessianApproximation::GaussNewton,
        integrator: IntegratorSettings::new(IntegratorKind::LawsonRk4, 16),
        kkt_tolerance: 1e-4,
        ..SqpSettings::default()
    };
    let lq = SqpSettings {
        mode: SqpMode::LinearQuadratic,
        globalisation: Globalisation::FullStep,
        max_iterations: 2,
        ..base.clone()
    };
    let mut lmpc = SqpSolver::new(model.clone(), ocp.clone(), lq)?;
    lmpc.solve(&x0)?;
    for (name, glob) in [
        ("merit line search", Globalisation::merit()),
        ("relaxation 0.5", Globalisation::FixedRelaxation { alpha: 0.5 }),
    ] {
        let s = SqpSettings { globalisation: glob, max_iterations: iters, ..base.clone() };
        let mut n = SqpSolver::new(model.clone(), ocp.clone(), s)?;
        for (d, s) in n.states_mut().iter_mut().zip(lmpc.states()) {
            d.copy_from(s);
        }
        for (d, s) in n.controls_mut().iter_mut().zip(lmpc.controls()) {
            d.copy_from(s);
        }
        let st = n.solve(&x0)?;
        println!("== {name} at t = {}: {:?}", row[0], st);
        for l in n.log() {
            println!(
                "  it {:2} cost {:.6e} kkt {:.2e} viol {:.2e} |Δw| {:.2e} t {:.3} qp {}",
                l.iteration,
                l.cost,
                l.kkt,
                l.constraint_violation,
                l.step_norm,
                l.step_length,
                l.qp_iterations
            );
        }
    }
    Ok(())
}
