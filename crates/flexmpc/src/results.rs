//! The results of closed loops as data: one run of a sweep ([`SweepRun`]) and the CSV files
//! of runs and sweeps, written through the `csv` crate (a name with a comma or a quote is
//! quoted, never splits a column).
//!
//! This module sits below the figures and the runs: both use it, it uses neither.

use std::path::Path;

use anyhow::{Context, Result};
use mpc::{ControllerKind, ModelKind, RunResult};

/// One run of a sweep.
pub struct SweepRun {
    /// Controller.
    pub controller: ControllerKind,
    /// The controller's reduced model.
    pub model: ModelKind,
    /// Disturbance.
    pub omega0: f64,
    /// The run, or why it could not run.
    pub result: std::result::Result<RunResult, String>,
}

impl SweepRun {
    /// `nmpc`, `lmpc`, or with the exact-joints model `nmpc-exact`: the name of the run's
    /// controller and model in tables and file names.
    pub fn label(&self) -> String {
        label(self.controller, self.model)
    }

    /// `<label>-w<ω0>`: the stem of the run's files in `runs/`.
    pub fn stem(&self) -> String {
        format!("{}-w{}", self.label(), self.omega0)
    }
}

/// `nmpc`, `lmpc`, or with the exact-joints model `nmpc-exact` (the paper's model has no
/// suffix, so paper-model sweeps keep their file names).
pub fn label(controller: ControllerKind, model: ModelKind) -> String {
    match model {
        ModelKind::Paper => controller.name().to_string(),
        ModelKind::ExactJoints => format!("{}-exact", controller.name()),
    }
}

/// The controllers of a sweep in order of first appearance.
pub fn sweep_kinds(runs: &[SweepRun]) -> Vec<ControllerKind> {
    let mut kinds: Vec<ControllerKind> = Vec::new();
    for r in runs {
        if !kinds.contains(&r.controller) {
            kinds.push(r.controller);
        }
    }
    kinds
}

/// The models of a sweep in order of first appearance.
pub fn sweep_models(runs: &[SweepRun]) -> Vec<ModelKind> {
    let mut models: Vec<ModelKind> = Vec::new();
    for r in runs {
        if !models.contains(&r.model) {
            models.push(r.model);
        }
    }
    models
}

fn writer(path: &Path) -> Result<csv::Writer<std::fs::File>> {
    csv::Writer::from_path(path).with_context(|| format!("creating {}", path.display()))
}

/// Writes the time series of a run: `t, V, V/V(0), u…, joint angles (deg)…, tip xyz, q…`.
pub fn write_timeseries(r: &RunResult, path: &Path) -> Result<()> {
    let mut f = writer(path)?;
    let mut cols = vec!["t".to_string(), "v_state".into(), "v_ratio".into()];
    cols.extend(r.input_names.iter().map(|n| format!("u:{n}")));
    cols.extend(r.joint_names.iter().map(|n| format!("angle_deg:{n}")));
    cols.extend(["tip.x", "tip.y", "tip.z"].map(String::from));
    let nq = r.records.first().map_or(0, |x| x.q.len());
    cols.extend((0..nq).map(|i| format!("q{i}")));
    f.write_record(&cols)?;
    let v0 = r.records.first().map_or(1.0, |x| x.v_state);
    for rec in &r.records {
        let mut row = vec![rec.t, rec.v_state, rec.v_state / v0];
        row.extend(&rec.u);
        row.extend(rec.joint_angles.iter().map(|a| a.to_degrees()));
        row.extend(rec.tip);
        row.extend(&rec.q);
        f.write_record(row.iter().map(|v| format!("{v:.10e}")))?;
    }
    f.flush().with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Columns of `sweep.csv`.
pub const SWEEP_COLUMNS: [&str; 19] = [
    "controller",
    "model",
    "plant",
    "omega0",
    "stabilised",
    "v_ratio_final",
    "max_joint_angle_deg",
    "orientation_error_deg",
    "max_orientation_deg",
    "rigid_rate_ratio",
    "failed_first_attempts",
    "relaxed_samples",
    "fallback_samples",
    "held_samples",
    "joint_limit_samples",
    "max_plan_joint_angle_deg",
    "samples",
    "t_end",
    "error",
];

/// Writes `sweep.csv`: one row per run, in the order of `runs`; a run that could not run has
/// `stabilised = false`, empty metrics and its error.
pub fn write_sweep_csv(runs: &[SweepRun], plant: &str, path: &Path) -> Result<()> {
    let mut f = writer(path)?;
    f.write_record(SWEEP_COLUMNS)?;
    for r in runs {
        match &r.result {
            Ok(res) => {
                let s = &res.summary;
                f.write_record([
                    s.controller.clone(),
                    s.model.clone(),
                    s.plant.clone(),
                    s.omega0.to_string(),
                    s.stabilised.to_string(),
                    format!("{:.6e}", s.v_ratio_final),
                    format!("{:.4}", s.max_joint_angle_deg),
                    format!("{:.4}", s.orientation_error_deg),
                    format!("{:.4}", s.max_orientation_deg),
                    format!("{:.6e}", s.rigid_rate_ratio),
                    s.failed_first_attempts.to_string(),
                    s.relaxed_samples.to_string(),
                    s.fallback_samples.to_string(),
                    s.held_samples.to_string(),
                    s.joint_limit_samples.to_string(),
                    format!("{:.4}", s.max_plan_joint_angle_deg),
                    res.samples.len().to_string(),
                    s.t_end.to_string(),
                    s.error.clone().unwrap_or_default(),
                ])?;
            }
            Err(e) => {
                let mut row = vec![
                    r.controller.name().to_string(),
                    r.model.name().to_string(),
                    plant.to_string(),
                    r.omega0.to_string(),
                    "false".into(),
                ];
                row.resize(SWEEP_COLUMNS.len() - 1, String::new());
                row.push(e.clone());
                f.write_record(&row)?;
            }
        }
    }
    f.flush().with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
