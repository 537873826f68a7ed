//! Real-time iteration study (issue 6, must-show 3): `rti [2d|3d] w1,w2,…` runs the NMPC
//! closed loop on the FE plant per ω0 (rayon-parallel) and prints the criterion, the
//! per-sample worst / median solve time (wall), and the run's wall and thread CPU time.
//! Env: `MPC_RTI=0` for the full SQP (default: RTI on), `MPC_GLOB=full|merit` (first
//! attempt's globalisation, default merit), `MPC_RETRY=off` (no relaxed retry: a failed or
//! out-of-range attempt goes straight to the linear MPC fallback), `MPC_MAXIT=N` (SQP
//! iteration limit when RTI is off), `MPC_HOLD=N` (fallback hold), `MPC_JLIM=deg|off` (plan
//! joint-angle limit), `MPC_PLANT=rom`.
use mpc::{run, ControllerKind, ControllerSettings, PlantKind, Scenario, Setup};
use ocp_transcription::Globalisation;
use rayon::prelude::*;

/// CPU time of the calling thread (s), from `/proc/thread-self/schedstat` (ns on CPU);
/// NaN where unavailable.
fn thread_cpu_s() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse::<f64>().ok()))
        .map_or(f64::NAN, |ns| ns * 1e-9)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let dim = a.get(1).map_or("2d", |s| s.as_str());
    let omegas: Vec<f64> = a
        .get(2)
        .map_or("0.25,0.5,0.75,1,1.25,1.5,1.75,2", |s| s.as_str())
        .split(',')
        .map(|s| s.parse())
        .collect::<Result<_, _>>()?;
    let scenario = if dim == "3d" { Scenario::paper_3d(50)? } else { Scenario::paper_2d(50)? };
    let setup = Setup::new(&scenario)?;
    let mut c = ControllerSettings::of(ControllerKind::Nmpc);
    c.real_time_iteration = std::env::var("MPC_RTI").map_or(true, |v| v != "0");
    if std::env::var("MPC_GLOB").as_deref() == Ok("full") {
        c.globalisation = Globalisation::FullStep;
    }
    if std::env::var("MPC_RETRY").as_deref() == Ok("off") {
        c.retry_relaxation = None;
    }
    if let Ok(n) = std::env::var("MPC_MAXIT") {
        c.max_iterations = n.parse()?;
    }
    if let Ok(n) = std::env::var("MPC_HOLD") {
        c.fallback_hold = n.parse()?;
    }
    if let Ok(v) = std::env::var("MPC_JLIM") {
        c.plan_joint_limit_deg = if v == "off" { None } else { Some(v.parse()?) };
    }
    let plant = if std::env::var("MPC_PLANT").as_deref() == Ok("rom") {
        PlantKind::Rom
    } else {
        PlantKind::Fe
    };
    let glob = if c.globalisation == Globalisation::FullStep { "full" } else { "merit" };
    let lines: Vec<String> = omegas
        .par_iter()
        .map(|&w| {
            let cpu0 = thread_cpu_s();
            let r = run(&setup, w, &c, plant);
            let cpu = thread_cpu_s() - cpu0;
            match r {
                Ok(r) => {
                    let s = &r.summary;
                    let mut t: Vec<f64> = r.samples.iter().map(|x| x.solve_time).collect();
                    t.sort_by(f64::total_cmp);
                    let n = t.len();
                    let iters: usize = r.samples.iter().map(|x| x.iterations).sum();
                    format!(
                        "{dim} rti={} maxit={} hold={} jlim={:?} glob={glob} retry={} w0={:.3} stab={} V={:.3e} joint={:.1}deg \
                         orient={:.2}/{:.1}deg rigid={:.3e} worst={:.3}s p90={:.3}s median={:.3}s \
                         iters={iters} failed1={} relaxed={} fallback={} held={} jlim={} \
                         wall={:.2}s cpu={:.2}s err={:?}",
                        c.real_time_iteration, c.max_iterations, c.fallback_hold, c.plan_joint_limit_deg, c.retry_relaxation.is_some(), w, s.stabilised, s.v_ratio_final,
                        s.max_joint_angle_deg, s.orientation_error_deg, s.max_orientation_deg,
                        s.rigid_rate_ratio, t[n - 1], t[(9 * n) / 10], t[n / 2],
                        s.failed_first_attempts, s.relaxed_samples, s.fallback_samples,
                        s.held_samples, s.joint_limit_samples, r.wall_time_s, cpu, s.error
                    )
                }
                Err(e) => format!("{dim} w0={w:.3} error: {e}"),
            }
        })
        .collect();
    for l in lines {
        println!("{l}");
    }
    Ok(())
}
