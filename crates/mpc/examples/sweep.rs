//! A sweep over ω0 of the paper's scenarios: `sweep [2d|3d] [nmpc|lmpc] [fe|rom] w1,w2,…`;
//! prints one summary line per run (rayon-parallel runs).
use mpc::{sweep, ControllerKind, ControllerSettings, PlantKind, Scenario, Setup};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let dim = a.get(1).map_or("2d", |s| s.as_str());
    let kind = match a.get(2).map_or("nmpc", |s| s.as_str()) {
        "lmpc" => ControllerKind::Lmpc,
        _ => ControllerKind::Nmpc,
    };
    let plant = match a.get(3).map_or("fe", |s| s.as_str()) {
        "rom" => PlantKind::Rom,
        _ => PlantKind::Fe,
    };
    let omegas: Vec<f64> = a
        .get(4)
        .map_or("0.25,0.5,0.75,1,1.25,1.5,1.75,2", |s| s.as_str())
        .split(',')
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    // `MPC_N=n`: n elements per link instead of the paper's 50
    let n_el: usize = std::env::var("MPC_N").map_or(Ok(50), |v| v.parse())?;
    let mut scenario =
        if dim == "3d" { Scenario::paper_3d(n_el)? } else { Scenario::paper_2d(n_el)? };
    match std::env::var("MPC_GRID").as_deref() {
        Ok("absolute") => scenario.mpc.control_grid = mpc::ControlGrid::Absolute,
        Ok("sample") => scenario.mpc.control_grid = mpc::ControlGrid::Sample,
        _ => {}
    }
    if let Ok(v) = std::env::var("MPC_KDXI") {
        scenario.mpc.k_dxi = v.parse()?;
    }
    if let Ok(v) = std::env::var("MPC_KU") {
        scenario.mpc.ku = v.parse()?;
    }
    if let Ok(v) = std::env::var("MPC_KX1") {
        scenario.mpc.kx1 = v.parse()?;
        scenario.mpc.kx2 = scenario.mpc.kx1;
    }
    if let Ok(v) = std::env::var("MPC_TS") {
        scenario.mpc.sampling = v.parse()?;
    }
    let setup = Setup::new(&scenario)?;
    let mut c = ControllerSettings::of(kind);
    c.real_time_iteration = std::env::var("MPC_RTI").is_ok();
    if let Ok(n) = std::env::var("MPC_SUBSTEPS") {
        c.integrator.substeps = n.parse()?;
    }
    if let Ok(v) = std::env::var("MPC_LM") {
        c.levenberg_marquardt = v.parse()?;
    }
    if let Ok(v) = std::env::var("MPC_JLIM") {
        c.plan_joint_limit_deg = if v == "off" { None } else { Some(v.parse()?) };
    }
    if let Ok(v) = std::env::var("MPC_HOLD") {
        c.fallback_hold = v.parse()?;
    }
    if let Ok(v) = std::env::var("MPC_RETRY_LM") {
        c.retry_levenberg_marquardt = v.parse()?;
    }
    if let Ok(v) = std::env::var("MPC_ALPHA") {
        c.retry_relaxation = Some(v.parse()?);
    }
    if std::env::var("MPC_NORETRY").is_ok() {
        c.retry_relaxation = None;
    }
    if std::env::var("MPC_NOFALLBACK").is_ok() {
        c.fallback_to_lmpc = false;
    }
    if std::env::var("MPC_FULLSTEP").is_ok() {
        c.globalisation = ocp_transcription::Globalisation::FullStep;
    }
    if let Ok(n) = std::env::var("MPC_ITER") {
        c.max_iterations = n.parse()?;
    }
    let monitor = mpc::JointMonitor::new(&setup)?;
    let results = sweep(&setup, &omegas, &c, plant, &|| {});
    for r in results {
        let r = r?;
        if std::env::var("MPC_TRACE").is_ok() {
            for smp in &r.samples {
                let k = ((smp.t / r.records[1].t).round() as usize).min(r.records.len() - 1);
                let rec = &r.records[k];
                println!(
                    "  t={:.2} {:?} first={} it={} planj={:.1} projj={:.1} joints={:?} V={:.3e} u={:?}",
                    smp.t, smp.strategy, smp.first_status, smp.iterations,
                    smp.plan_joint_angle_deg.unwrap_or(f64::NAN),
                    monitor.max_angle(&rec.q).to_degrees(),
                    rec.joint_angles.iter().map(|a| (a.to_degrees() * 10.0).round() / 10.0).collect::<Vec<_>>(),
                    rec.v_state, smp.u.iter().map(|a| (a * 100.0).round() / 100.0).collect::<Vec<_>>()
                );
            }
        }
        let s = &r.summary;
        println!(
            "{} {} {} w0={:.3} stab={} V={:.3e} joint={:.1}deg orient={:.2}/{:.1}deg rigid={:.3e} \
             worst={:.3}s median={:.3}s failed1={} relaxed={} fallback={} held={} jlim={} planj={:.1} t_end={} err={:?} wall={:.1}s",
            dim, s.controller, s.plant, s.omega0, s.stabilised, s.v_ratio_final,
            s.max_joint_angle_deg, s.orientation_error_deg, s.max_orientation_deg,
            s.rigid_rate_ratio, s.solve_time_worst_s, s.solve_time_median_s,
            s.failed_first_attempts, s.relaxed_samples, s.fallback_samples, s.held_samples, s.joint_limit_samples,
            s.max_plan_joint_angle_deg, s.t_end, s.error,
            r.wall_time_s
        );
    }
    Ok(())
}
