//! A sweep over the disturbance ω0 of the paper's scenarios:
//! `cargo run --release -p mpc --example sweep -- [2d|3d] [nmpc|lmpc] [fe|rom] w1,w2,…`;
//! prints one summary line per run (runs in parallel, each deterministic). Controller and
//! horizon variants are scene keys of `flexmpc sweep <scene> --omega0 …` (`[controller]`,
//! `[scenario]`).
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
    let scenario = if dim == "3d" { Scenario::paper_3d(50)? } else { Scenario::paper_2d(50)? };
    let setup = Setup::new(&scenario)?;
    let c = ControllerSettings::of(kind);
    let results = sweep(&setup, &omegas, &c, plant, &|| {});
    for r in results {
        let r = r?;
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
