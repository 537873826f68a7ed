//! One closed loop of the paper's scenarios:
//! `cargo run --release -p mpc --example closed_loop -- [2d|3d] [nmpc|lmpc] [fe|rom] [ω0] [every]`.
//!
//! Builds the scenario (two links, 50 elements each, disturbance ω0 about the root), the
//! precomputed modes and reduced model ([`Setup`]), and runs the controller against the plant;
//! prints one line per control sample (status, strategy, SQP iterations, solve time, cost),
//! every `every`-th state record (cost `V`, joint angles, tip) and the run summary.
use mpc::{run, ControllerKind, ControllerSettings, PlantKind, Scenario, Setup};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let dim = a.get(1).map_or("2d", |s| s.as_str());
    let kind = match a.get(2).map_or("nmpc", |s| s.as_str()) {
        "lmpc" => ControllerKind::Lmpc,
        _ => ControllerKind::Nmpc,
    };
    let plant = match a.get(3).map_or("rom", |s| s.as_str()) {
        "fe" => PlantKind::Fe,
        _ => PlantKind::Rom,
    };
    let omega0: f64 = a.get(4).map_or(Ok(1.0), |s| s.parse())?;
    let scenario = if dim == "3d" { Scenario::paper_3d(50)? } else { Scenario::paper_2d(50)? };
    let t = std::time::Instant::now();
    let setup = Setup::new(&scenario)?;
    eprintln!("setup {:?}", t.elapsed());
    let c = ControllerSettings::of(kind);
    let r = run(&setup, omega0, &c, plant)?;
    for s in &r.samples {
        println!(
            "t={:.2} {} {:?} it={} time={:.4} cost={:.4e} kkt={:.1e} u={:?}",
            s.t, s.status, s.strategy, s.iterations, s.solve_time, s.cost, s.kkt, s.u
        );
    }
    let every = a.get(5).map_or(Ok(10), |s| s.parse())?;
    for rec in r.records.iter().step_by(every) {
        println!(
            "t={:.2} V={:.4e} angles={:.4?} tip={:.4?} u={:.3?} q={:.3?}",
            rec.t, rec.v_state, rec.joint_angles, rec.tip, rec.u, rec.q
        );
    }
    println!("{:#?}\nwall {:.2} s", r.summary, r.wall_time_s);
    Ok(())
}
