//! Verification case `mpc/shipped-scenes`: every closed-loop scene shipped in `scenes/` run
//! at its own defaults (its `[scenario]` ω0, plant and `[controller]`), as `flexmpc mpc
//! SCENE` runs it. Each must meet its criterion ([`mpc::RunSummary::stabilised`]:
//! stabilisation, or the joint commands of a reconfiguration scene), and a scene whose
//! controller is real time (one SQP iteration per sample, or the linear MPC) must solve
//! every sample within the sampling time τs. Solve times are the controller's CPU time per
//! thread per sample (`mpc::RunSummary::solve_cpu_per_thread_worst_s`: the calling thread's
//! CPU time, or with `parallel_intervals` all threads' CPU time over the pool size), so a
//! loaded machine does not fail the case.

use crate::{Case, CaseOutcome, Metric, Tier};
use mpc::Setup;

/// The cases.
pub fn cases() -> Vec<Case> {
    vec![Case { name: "mpc/shipped-scenes", tier: Tier::Full, run: shipped_scenes }]
}

/// The shipped scenes with a `[scenario]` (closed loop), by file name.
const SCENES: &[(&str, &str)] = &[
    ("paper-2d-mpc.toml", include_str!("../../scenes/paper-2d-mpc.toml")),
    ("paper-2d-mpc-exact-joints.toml", include_str!("../../scenes/paper-2d-mpc-exact-joints.toml")),
    ("paper-3d-mpc.toml", include_str!("../../scenes/paper-3d-mpc.toml")),
    ("paper-3d-mpc-full-range.toml", include_str!("../../scenes/paper-3d-mpc-full-range.toml")),
    ("paper-3d-mpc-paper-model.toml", include_str!("../../scenes/paper-3d-mpc-paper-model.toml")),
    ("paper-3d-mpc-ku1.toml", include_str!("../../scenes/paper-3d-mpc-ku1.toml")),
    ("fold-2d.toml", include_str!("../../scenes/fold-2d.toml")),
    ("fold-3d.toml", include_str!("../../scenes/fold-3d.toml")),
];

fn shipped_scenes() -> CaseOutcome {
    let mut out = Vec::new();
    for (name, text) in SCENES {
        let scene = flexmpc::scene::load_str(std::path::Path::new(name), text)
            .map_err(|e| e.to_string())?;
        let control = scene.control.as_ref().ok_or(format!("{name}: no [scenario]"))?;
        let setup = Setup::new(&control.scenario).map_err(|e| format!("{name}: {e}"))?;
        let c = &control.controller;
        let r = mpc::run(&setup, control.omega0, c, control.plant)
            .map_err(|e| format!("{name}: {e}"))?;
        let s = &r.summary;
        if let Some(e) = &s.error {
            return Err(format!("{name}: run stopped at t = {}: {e}", s.t_end));
        }
        out.push(Metric::at_least(
            format!("{name}: criterion met at its default ω0 = {} (0/1)", control.omega0),
            if s.stabilised { 1.0 } else { 0.0 },
            1.0,
        ));
        let tau = control.scenario.mpc.timing.sampling;
        let real_time = c.kind == mpc::ControllerKind::Lmpc || c.real_time_iteration;
        out.push(Metric::at_most(
            format!(
                "{name}: worst per-sample solve, thread CPU / τs = {tau} s{}",
                if real_time { "" } else { " (full SQP: report)" }
            ),
            s.solve_cpu_per_thread_worst_s / tau,
            if real_time { 1.0 } else { f64::INFINITY },
        ));
    }
    Ok(out)
}
