//! Export of one sample's optimal control problem (the first sample of a run), so that any
//! other solver can solve exactly the same problem: the controller model (modal-rom's JSON +
//! `.npy` export of the paper's model, or of the exact-joints model, theory.md §10) plus
//! `ocp.json` with weights, references, bounds, horizon, `Nc`, integrator and initial state.

use crate::controller::ControllerSettings;
use crate::error::{invalid, MpcError, Result};
use crate::exact_dynamics::{default_link_elastic_modes, ExactDynamics};
use crate::reference::ReferenceSchedule;
use crate::scenario::Setup;
use crate::weights::Weights;
use ocp_transcription::{IntegratorKind, IntegratorSettings};
use serde::{Deserialize, Serialize};
use std::path::Path;

fn paper_model() -> String {
    "paper".into()
}

const COST: &str =
    "J = Σ_k c_k Δt ½(s_k − x_ref,k)ᵀQ(s_k − x_ref,k) + Σ_k Δt ½(u_k − u_ref)ᵀR(u_k − u_ref), \
    c_0 = c_Nc = ½, else 1 (trapezoidal on the shooting nodes), Δt = horizon/intervals";

fn newton_tolerance(int: &IntegratorSettings) -> Option<f64> {
    (int.kind == IntegratorKind::ImplicitMidpoint).then_some(int.newton_tolerance)
}

fn write_ocp(p: &OcpExport, dir: &Path) -> Result<()> {
    let text = serde_json::to_string_pretty(p)
        .map_err(|e| invalid("ocp.json", "serialisation", e.to_string()))?;
    let path = dir.join("ocp.json");
    std::fs::write(&path, text).map_err(|e| MpcError::Invalid {
        field: path.display().to_string(),
        value: "write".into(),
        reason: e.to_string(),
    })
}

/// The optimal control problem (33)–(35) of one sample, in plain data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OcpExport {
    /// Format tag `flexmpc-ocp`.
    pub format: String,
    /// Format version (1).
    pub version: u32,
    /// Controller model: `paper` (modal-rom's `flexmpc-modal-rom` export) or `exact-joints`
    /// (`flexmpc-exact-joints-rom`).
    #[serde(default = "paper_model")]
    pub model: String,
    /// `nmpc` (the nonlinear model) or `lmpc` (the model linearised at `x_ref`, `u_ref`).
    pub controller: String,
    /// Disturbance magnitude of the run (rad/s).
    pub omega0: f64,
    /// Horizon `τp` (s).
    pub horizon: f64,
    /// Control intervals `Nc` (piecewise-constant `u`).
    pub intervals: usize,
    /// Sampling time `τs` (s) of the closed loop.
    pub sampling: f64,
    /// State weight `Q`, row-major `n × n`.
    pub q: Vec<Vec<f64>>,
    /// Input weight `R`, row-major.
    pub r: Vec<Vec<f64>>,
    /// State reference.
    pub x_ref: Vec<f64>,
    /// State references at the shooting nodes `s_0 … s_Nc` when they vary along the horizon
    /// (joint commands); `x_ref` is then the first one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub x_ref_nodes: Option<Vec<Vec<f64>>>,
    /// Input reference.
    pub u_ref: Vec<f64>,
    /// Lower input bounds.
    pub u_min: Vec<f64>,
    /// Upper input bounds.
    pub u_max: Vec<f64>,
    /// Initial modal state `q_a(0)` (projection of the FE state).
    pub x0: Vec<f64>,
    /// Integrator inside each interval (`Debug` name) and its substeps.
    pub integrator: String,
    /// Substeps per interval (before `tail_from_interval`).
    pub substeps: usize,
    /// The intervals from this one on take `tail_substeps` substeps
    /// (`ocp_transcription::IntegratorSettings::tail`; absent: every interval `substeps`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tail_from_interval: Option<usize>,
    /// Substeps of each interval from `tail_from_interval` on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tail_substeps: Option<usize>,
    /// Newton tolerance of the implicit midpoint rule on `‖r‖∞ / (1 + ‖m‖∞)` (`r` the residual
    /// of `m − x − h/2 f(m, u) = 0`, `x⁺ = 2m − x`), when that is the integrator.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub newton_tolerance: Option<f64>,
    /// How the cost is discretised.
    pub cost_discretisation: String,
    /// Input names, in the order of `u`.
    pub inputs: Vec<String>,
}

/// The first sample's problem of a run with disturbance `omega0`.
pub fn first_sample_problem(
    setup: &Setup,
    omega0: f64,
    controller: &ControllerSettings,
) -> Result<OcpExport> {
    if !omega0.is_finite() {
        return Err(invalid("omega0", omega0, "must be finite"));
    }
    let sc = &setup.scenario;
    let x0 = sc.disturbed_state(omega0);
    let xi: Vec<[f64; 4]> = sc
        .structure
        .reference()
        .iter()
        .flat_map(|k| k.xi.iter().map(|v| [v[0], v[1], v[2], v[3]]))
        .collect();
    let q0 = setup.rom.project_full(&x0, Some(&xi))?;
    let rows = |m: &nalgebra::DMatrix<f64>| -> Vec<Vec<f64>> {
        (0..m.nrows()).map(|i| m.row(i).iter().copied().collect()).collect()
    };
    let nu = setup.rom.n_inputs();
    Ok(OcpExport {
        format: "flexmpc-ocp".into(),
        version: 1,
        model: paper_model(),
        controller: controller.kind.name().into(),
        omega0,
        horizon: sc.mpc.timing.horizon,
        intervals: sc.mpc.timing.intervals,
        sampling: sc.mpc.timing.sampling,
        q: rows(&setup.weights.q),
        r: rows(&setup.weights.r),
        x_ref: setup.weights.x_ref.iter().copied().collect(),
        x_ref_nodes: None,
        u_ref: vec![0.0; nu],
        u_min: vec![-sc.mpc.cost.u_max; nu],
        u_max: vec![sc.mpc.cost.u_max; nu],
        x0: q0,
        integrator: format!("{:?}", controller.integrator.kind),
        substeps: controller.integrator.substeps,
        tail_from_interval: controller.integrator.tail.map(|t| t.from_interval),
        tail_substeps: controller.integrator.tail.map(|t| t.substeps),
        newton_tolerance: newton_tolerance(&controller.integrator),
        cost_discretisation: COST.into(),
        inputs: setup.rom.input_names().to_vec(),
    })
}

/// Writes the modal model (modal-rom's export) and `ocp.json` of the first sample to `dir`.
/// For `lmpc` the dynamics are those of the exported model linearised at `(x_ref, u_ref)`.
pub fn export_first_sample(
    setup: &Setup,
    omega0: f64,
    controller: &ControllerSettings,
    dir: &Path,
) -> Result<OcpExport> {
    let p = first_sample_problem(setup, omega0, controller)?;
    setup.rom.export(dir)?;
    write_ocp(&p, dir)?;
    Ok(p)
}

/// The first sample's problem on the exact-joints model (theory.md §10.8): the model, its
/// weights, the reference schedule of the scenario's joint commands (`None` without
/// commands) and the initial state, the FE state of a run with disturbance `omega0` projected
/// onto the exact-joints state (what the closed loop's first sample starts from).
#[derive(Clone, Debug)]
pub struct ExactFirstSample {
    /// The controller model.
    pub dynamics: ExactDynamics,
    /// Weights and (constant) reference.
    pub weights: Weights,
    /// The joint commands' references over time.
    pub schedule: Option<ReferenceSchedule>,
    /// Initial state `x(0)`.
    pub x0: Vec<f64>,
}

/// [`ExactFirstSample`] of a run with disturbance `omega0` and the controller `controller`
/// (its [`ControllerSettings::link_elastic_modes`]).
pub fn first_sample_exact(
    setup: &Setup,
    omega0: f64,
    controller: &ControllerSettings,
) -> Result<ExactFirstSample> {
    if !omega0.is_finite() {
        return Err(invalid("omega0", omega0, "must be finite"));
    }
    let sc = &setup.scenario;
    let elastic = controller
        .link_elastic_modes
        .unwrap_or_else(|| default_link_elastic_modes(setup.planar_axis.is_none()));
    let (dynamics, weights) = ExactDynamics::for_setup(setup, elastic)?;
    let x_fe = sc.disturbed_state(omega0);
    let x0 = dynamics.rom().project_fe(&x_fe, sc.structure.reference())?;
    let schedule = if sc.references.is_empty() {
        None
    } else {
        Some(dynamics.reference_schedule(setup, &weights)?)
    };
    Ok(ExactFirstSample { dynamics, weights, schedule, x0 })
}

impl ExactFirstSample {
    /// The problem in plain data ([`OcpExport`], `model = "exact-joints"`): weights, the
    /// reference (at the shooting nodes' times when the scenario commands joints), bounds,
    /// timing and integrator of `controller`, initial state.
    pub fn problem(
        &self,
        setup: &Setup,
        omega0: f64,
        controller: &ControllerSettings,
    ) -> OcpExport {
        let sc = &setup.scenario;
        let timing = &sc.mpc.timing;
        let rows = |m: &nalgebra::DMatrix<f64>| -> Vec<Vec<f64>> {
            (0..m.nrows()).map(|i| m.row(i).iter().copied().collect()).collect()
        };
        let rom = self.dynamics.rom();
        let nu = rom.n_inputs();
        let (x_ref, x_ref_nodes) = match &self.schedule {
            Some(s) => (
                s.at(0.0),
                Some(s.nodes(0.0, timing.horizon / timing.intervals as f64, timing.intervals)),
            ),
            None => (self.weights.x_ref.iter().copied().collect(), None),
        };
        OcpExport {
            format: "flexmpc-ocp".into(),
            version: 1,
            model: "exact-joints".into(),
            controller: controller.kind.name().into(),
            omega0,
            horizon: timing.horizon,
            intervals: timing.intervals,
            sampling: timing.sampling,
            q: rows(&self.weights.q),
            r: rows(&self.weights.r),
            x_ref,
            x_ref_nodes,
            u_ref: vec![0.0; nu],
            u_min: vec![-sc.mpc.cost.u_max; nu],
            u_max: vec![sc.mpc.cost.u_max; nu],
            x0: self.x0.clone(),
            integrator: format!("{:?}", controller.integrator.kind),
            substeps: controller.integrator.substeps,
            tail_from_interval: controller.integrator.tail.map(|t| t.from_interval),
            tail_substeps: controller.integrator.tail.map(|t| t.substeps),
            newton_tolerance: newton_tolerance(&controller.integrator),
            cost_discretisation: COST.into(),
            inputs: rom.input_names().to_vec(),
        }
    }
}

/// Writes the exact-joints model (`ExactJointsRom::export`) and `ocp.json` of the first
/// sample on it (theory.md §10.8) to `dir`; returns the sample and the problem.
pub fn export_first_sample_exact(
    setup: &Setup,
    omega0: f64,
    controller: &ControllerSettings,
    dir: &Path,
) -> Result<(ExactFirstSample, OcpExport)> {
    let sample = first_sample_exact(setup, omega0, controller)?;
    let p = sample.problem(setup, omega0, controller);
    sample.dynamics.rom().export(dir)?;
    write_ocp(&p, dir)?;
    Ok((sample, p))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ModelKind, Scenario};

    /// The exact-joints first sample exported and re-read: the problem as written, the model's
    /// export with the state size and reference state of the controller model.
    #[test]
    fn exact_joints_export_round_trip() {
        let sc = Scenario::paper_2d(8).unwrap();
        let setup = Setup::new(&sc).unwrap();
        let c =
            ControllerSettings { model: ModelKind::ExactJoints, ..ControllerSettings::full_sqp() };
        let dir = std::env::temp_dir().join(format!("mpc-export-exact-{}", std::process::id()));
        let (sample, p) = export_first_sample_exact(&setup, 0.5, &c, &dir).unwrap();
        let text = std::fs::read_to_string(dir.join("ocp.json")).unwrap();
        let back: OcpExport = serde_json::from_str(&text).unwrap();
        let (meta, arrays) = modal_rom::read_exact_joints(&dir).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back, p);
        assert_eq!(p.model, "exact-joints");
        let rom = sample.dynamics.rom();
        assert_eq!(
            (meta.n_state, p.x0.len(), p.q.len()),
            (rom.n_state(), rom.n_state(), rom.n_state())
        );
        assert_eq!(meta.reference_state, rom.reference_state());
        assert_eq!(p.x0, sample.x0);
        assert_eq!(p.x_ref, sample.weights.x_ref.iter().copied().collect::<Vec<_>>());
        assert_eq!(arrays["z0"].shape, vec![meta.n_fields, rom.n_p()]);
        assert_eq!(p.inputs, rom.input_names());
        assert_eq!(p.newton_tolerance.is_some(), p.integrator == "ImplicitMidpoint");
    }
}
