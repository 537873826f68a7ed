//! The scene file's tables as serde types (the file's syntax and types; the rules are checked
//! when the scene is built).

use serde::Deserialize;
use toml::Spanned;

use super::names::{
    ComponentsName, FreedomName, JointKindName, LoadFrameName, ModeSet, SectionPreset,
};

/// A section: a preset of the paper or explicit diagonals.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SectionSpec {
    /// `paper-2d` or `paper-3d` (theory.md §9), or absent for explicit values.
    pub preset: Option<SectionPreset>,
    /// Remove all damping (default false).
    #[serde(default)]
    pub undamped: bool,
    /// Diagonal of `M` (6 entries; 0 = massless).
    pub mass: Option<[f64; 6]>,
    /// Diagonal of `C⁻¹` (6 entries; `inf` = rigid).
    pub stiffness: Option<[f64; 6]>,
    /// Diagonal of `D2` (6 entries, ≥ 0).
    pub d2: Option<[f64; 6]>,
    /// Multiply every stiffness by this factor (default 1).
    pub stiffness_factor: Option<f64>,
    /// Initial curvature/twist `κ0` (local frame, 3 entries).
    pub kappa0: Option<[f64; 3]>,
}

/// A rotation by an angle (degrees) about an axis.
#[derive(Debug, Deserialize, Clone, Copy)]
#[serde(deny_unknown_fields)]
pub struct RotationSpec {
    /// Axis (any non-zero length).
    pub axis: [f64; 3],
    /// Angle in degrees.
    pub angle_deg: f64,
}

/// Attachment of a beam's start to a joint.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttachSpec {
    /// Joint name.
    pub joint: String,
    /// Axis in the joint's first end frame (default e2).
    #[serde(default = "default_axis")]
    pub axis: [f64; 3],
    /// Reference joint angle (degrees, default 0).
    #[serde(default)]
    pub angle_deg: f64,
}

fn default_axis() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

/// A beam.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeamSpec {
    /// Unique name.
    pub name: String,
    /// Name of a `[sections.*]` entry.
    pub section: String,
    /// Length (> 0).
    pub length: f64,
    /// Number of elements (≥ 1).
    pub elements: usize,
    /// Position of the `s = 0` end (default origin); exclusive with `attach`.
    pub origin: Option<[f64; 3]>,
    /// Orientation of the `s = 0` end (default: along global e1).
    pub rotation: Option<RotationSpec>,
    /// Place the start at a joint instead.
    pub attach: Option<AttachSpec>,
}

/// A joint or support kind with its parameters.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// Unique name.
    pub name: String,
    /// `weld`, `ball`, `hinge`, `universal` or `custom`.
    pub kind: JointKindName,
    /// Joints: the ends, `"beam:start"` / `"beam:end"` (at least 2).
    pub ends: Option<Vec<String>>,
    /// Supports: the end, `"beam:start"` / `"beam:end"`.
    pub end: Option<String>,
    /// Hinge axis.
    pub axis: Option<[f64; 3]>,
    /// Frame of the hinge axis / custom axes: `global`, `each-end`, or `end-N` (N-th end).
    pub frame: Option<String>,
    /// Custom: `rigid`/`free` per translation axis.
    pub translation: Option<[FreedomName; 3]>,
    /// Custom: `rigid`/`free` per rotation axis.
    pub rotation: Option<[FreedomName; 3]>,
    /// Custom: frame of the rotation axes (default: `frame`).
    pub rotation_frame: Option<String>,
    /// Custom: the three axes (orthonormal columns in their frame; default e1, e2, e3).
    pub axes: Option<[[f64; 3]; 3]>,
}

/// A time history of an input.
#[derive(Debug, Deserialize, Clone)]
#[serde(deny_unknown_fields)]
pub struct AmplitudeSpec {
    /// Linear ramp from 0 to 1 over this many seconds.
    pub ramp: Option<f64>,
    /// Piecewise linear `[[t, a], …]`.
    pub table: Option<Vec<[f64; 2]>>,
}

/// A node of a beam: an index or `start`/`end`.
#[derive(Debug, Deserialize, Clone)]
#[serde(untagged)]
pub enum NodeSpec {
    /// Node index `0..=N`.
    Index(usize),
    /// `start` or `end`.
    Named(String),
}

/// A point load.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSpec {
    /// Optional name (CSV column `input:<name>`).
    pub name: Option<String>,
    /// Beam name.
    pub beam: String,
    /// Node.
    pub node: NodeSpec,
    /// `follower` (local frame) or `dead` (global frame).
    pub frame: LoadFrameName,
    /// Force (3 components; default 0).
    pub force: Option<[f64; 3]>,
    /// Moment (3 components; default 0).
    pub moment: Option<[f64; 3]>,
    /// Time history (default constant 1).
    pub amplitude: Option<AmplitudeSpec>,
    /// A control input of `flexmpc mpc`/`sweep` (default false): `force`/`moment` are then
    /// the input's unit load `[f, m]` (follower frame only, no `amplitude`), scaled by the
    /// controller's `u`; `simulate` applies it with `u = 0`.
    #[serde(default)]
    pub control: bool,
}

/// A torque at a joint or support about its free rotation axis.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TorqueSpec {
    /// Joint or support name.
    pub joint: String,
    /// Active-axis index if the joint has several free rotation axes.
    pub axis: Option<usize>,
    /// Torque value.
    pub value: f64,
    /// Time history (default constant 1).
    pub amplitude: Option<AmplitudeSpec>,
    /// A control input of `flexmpc mpc`/`sweep` (default false): the controller sets the
    /// torque (N·m) directly, so `value` must be 1 and `amplitude` absent; `simulate`
    /// applies 0.
    #[serde(default)]
    pub control: bool,
}

/// A rigid-body velocity field on some beams.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigidSpec {
    /// Beams it applies to (default: all).
    pub beams: Option<Vec<String>>,
    /// Angular velocity (global, rad/s).
    pub omega: [f64; 3],
    /// Centre of rotation (default origin).
    pub center: Option<[f64; 3]>,
}

/// Initial conditions.
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct InitialSpec {
    /// Rigid rotations (added in order; later entries overwrite their beams).
    #[serde(default)]
    pub rigid: Vec<Spanned<RigidSpec>>,
}

/// Run settings.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    /// Time step (s).
    pub dt: f64,
    /// Duration (s).
    pub duration: f64,
    /// Write every this many steps (default 10).
    pub output_every: Option<usize>,
    /// Newton tolerance (default 1e-12).
    pub newton_tolerance: Option<f64>,
}

/// Output options.
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// CSV columns to plot in `plot.svg` (e.g. `b.end.z`).
    #[serde(default)]
    pub plot: Vec<String>,
    /// Title of the plot.
    pub title: Option<String>,
}

/// `[modes]`: what `flexmpc modes` lists and the mode set of the controller's reduced model.
///
/// The controller's set is given by at most one of `selection`, `kinds`, `lowest`,
/// `indices`; `flexmpc mpc`/`sweep` need one of them.
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ModesSpec {
    /// Number of modes (rigid ones included) listed and plotted by `flexmpc modes` and in
    /// the report (default 8); ≥ 1. `--modes` overrides.
    pub count: Option<usize>,
    /// Reference angles (degrees, finite) of the structure's first joint at which
    /// `flexmpc modes` computes the modes, e.g. `[0, 45, 90]` (paper Figs. 4–5) [the angle of
    /// the scene's `attach`]; needs a beam placed by `attach`. `--angle` overrides.
    pub angles: Option<Vec<f64>>,
    /// Controller model: a named set, `paper-2d` (2 rigid + 4 axial + 4 bending, §5.2) or
    /// `paper-3d` (4 rigid + 4 axial + 4 torsion + 4 + 4 bending, §5.3).
    pub selection: Option<ModeSet>,
    /// Controller model: the lowest modes of each kind (counts `rigid`, `axial`, `torsion`,
    /// `bending_e2`, `bending_e3`, `mixed`; absent ones 0; total ≥ 1).
    pub kinds: Option<modal_rom::KindCounts>,
    /// Controller model: the lowest `n` modes (rigid first), n ≥ 1.
    pub lowest: Option<usize>,
    /// Controller model: explicit mode indices (0-based, basis order: rigid first, then by
    /// frequency), non-empty.
    pub indices: Option<Vec<usize>>,
}

/// `[controller]`: which MPC and its solver settings. An absent key keeps the default of
/// [`mpc::ControllerSettings`] (the library's `Default`, with the exact-joints model's own
/// defaults for `joint_limit` and `fallback_to_lmpc`); the ranges are its `validate()`'s. The
/// keys that are the library's fields carry its names; `line_search`, `retry`,
/// `joint_limit`, `integrator` and `substeps` are the scene's switches onto them.
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ControllerSpec {
    /// `nmpc` (SQP on the augmented modal model) or `lmpc` (one QP on the model linearised
    /// at the reference). `--controller` overrides.
    pub kind: Option<mpc::ControllerKind>,
    /// One SQP iteration per sample from the shifted plan instead of iterating to the KKT
    /// tolerance.
    pub real_time_iteration: Option<bool>,
    /// Step of the NMPC's first attempt: `true` merit line search, `false` full Gauss–Newton
    /// step.
    pub line_search: Option<bool>,
    /// SQP iteration limit per sample (≥ 1).
    pub max_iterations: Option<usize>,
    /// Full SQP only: SQP iterations (≥ 1) the first sample runs from its initial guess
    /// before its ordinary solve of up to `max_iterations` more.
    pub first_sample_iterations: Option<usize>,
    /// Initial guess of the first sample's NMPC solve: `linear-mpc` (the linear MPC plan) or
    /// `decay` (shooting nodes on the line from the measured state to the reference,
    /// reference controls).
    pub first_sample_guess: Option<mpc::InitialGuess>,
    /// With `first_sample_iterations`: steps `m` (≥ 1) of the continuation in the initial
    /// state — the first sample's iterations run for `x_r + (j/m)(x0 − x_r)`, `j = 1…m`,
    /// each from the previous solution (1: none).
    pub first_sample_continuation: Option<usize>,
    /// With `first_sample_iterations`: Levenberg–Marquardt term (≥ 0) of the first sample's
    /// extra iterations (default: `levenberg_marquardt`).
    pub first_sample_levenberg_marquardt: Option<f64>,
    /// Later samples: re-simulate the first this-many nodes of the shifted plan from the
    /// measured state with the plan's controls before solving (0: the shifted plan as is).
    pub rollout_intervals: Option<usize>,
    /// With `line_search = true`: the second-order-corrected merit line search (adaptive
    /// penalty, corrections of the shooting defects) instead of the plain merit line search.
    pub second_order_correction: Option<bool>,
    /// KKT tolerance of the SQP (> 0).
    pub kkt_tolerance: Option<f64>,
    /// An iteration-limit plan is accepted when its shooting defects are at most this
    /// (> 0).
    pub accept_violation: Option<f64>,
    /// Levenberg–Marquardt term of the first SQP attempt (≥ 0).
    pub levenberg_marquardt: Option<f64>,
    /// On failure, retry from the linear MPC plan with the paper's sub-relaxation.
    pub retry: Option<bool>,
    /// Sub-relaxation factor `α` of the retry, in (0, 1].
    pub retry_relaxation: Option<f64>,
    /// Levenberg–Marquardt term of the retry (≥ 0).
    pub retry_levenberg_marquardt: Option<f64>,
    /// When every NMPC attempt fails, apply the linear MPC plan.
    pub fallback_to_lmpc: Option<bool>,
    /// Check each NMPC plan's predicted joint angles against `plan_joint_limit_deg` and treat
    /// a plan beyond it as a failed attempt.
    pub joint_limit: Option<bool>,
    /// Range of validity of the controller model for that check (deg, in (0, 180]).
    pub plan_joint_limit_deg: Option<f64>,
    /// Integrator in each shooting interval: `lawson-rk4`, `rk4` or `implicit-midpoint`
    /// (the library's [`ocp_transcription::IntegratorKind`]; default that of
    /// [`mpc::ControllerSettings`]).
    pub integrator: Option<ocp_transcription::IntegratorKind>,
    /// Integrator substeps per shooting interval `τp/Nc` (≥ 1).
    pub substeps: Option<usize>,
    /// With `tail_substeps`: the first shooting interval (≥ 1, below the interval count) of
    /// the horizon's tail, whose intervals take `tail_substeps` substeps instead of
    /// `substeps` ([`ocp_transcription::IntegratorSettings::tail`]).
    pub tail_from_interval: Option<usize>,
    /// With `tail_from_interval`: substeps (≥ 1) of each interval of the horizon's tail.
    pub tail_substeps: Option<usize>,
    /// Newton tolerance of the implicit midpoint rule in the shooting intervals, on
    /// `‖r‖∞ / (1 + ‖m‖∞)`, in (0, 1e-2] (default that of
    /// [`ocp_transcription::IntegratorSettings`]).
    pub newton_tolerance: Option<f64>,
    /// Weights of the cost (34)–(36) and the input bound: the library's own settings
    /// ([`mpc::CostWeights`], the paper's values by default).
    pub weights: Option<Spanned<mpc::CostWeights>>,
    /// The controller's reduced model: `paper` (the paper's augmented modal model) or
    /// `exact-joints` (joint rows at the current relative rotation, docs/theory.md §10; NMPC
    /// on the FE plant only, and without the joint-angle check, which is off by default with
    /// it). `--model` overrides.
    pub model: Option<mpc::ModelKind>,
    /// `exact-joints` only: elastic modes per link of its basis (rigid link motions + this
    /// many of the lowest constrained modes, split per link).
    pub link_elastic_modes: Option<usize>,
    /// Integrate the NMPC's shooting intervals on the rayon pool (`--threads`); same results
    /// for any pool size, on or off ([`mpc::ControllerSettings::parallel_intervals`]).
    pub parallel_intervals: Option<bool>,
}

/// `[scenario]`: one closed-loop stabilisation run (paper §5.2–5.3) of `flexmpc mpc`.
/// The structure and its control inputs (`control = true` loads and torques, in the order
/// they appear in the file: the order of `u`) are the scene's; the plant's time step is `[run] dt`. Defaults are the paper's.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioSpec {
    /// Disturbance magnitude `ω0` (rad/s, finite) (default 1). `--omega0` overrides.
    pub omega0: Option<f64>,
    /// Axis of the initial rigid rotation (global, non-zero): the initial rate is
    /// `ω0 · axis`, not normalised (the paper's 3D case: `[0, 1, 1]`, magnitude `√2 ω0`).
    pub axis: [f64; 3],
    /// Centre of the initial rigid rotation (global, m) (default origin).
    pub center: Option<[f64; 3]>,
    /// Support whose angle measures the root link's orientation [the first support].
    pub root: Option<String>,
    /// Duration of the closed loop (s, > 0, a multiple of `output_interval`) [7.5].
    /// `--duration` overrides.
    pub duration: Option<f64>,
    /// `horizon` (`τp`), `sampling` (`τs`, also a multiple of `output_interval`) and
    /// `intervals` (`Nc`): the library's own settings ([`mpc::Timing`], the paper's by
    /// default).
    #[serde(flatten)]
    pub timing: mpc::Timing,
    /// Plant: `fe` (the constrained FE model, the paper's) or `rom` (the modal model
    /// itself, fast studies) (default fe). `--plant` overrides.
    pub plant: Option<mpc::PlantKind>,
    /// Interval of the recorded time series (s, a multiple of `[run] dt`) [0.05].
    pub output_interval: Option<f64>,
    /// Interval of the snapshots of the deformed structure (s, a multiple of
    /// `output_interval`) [0.25].
    pub snapshot_interval: Option<f64>,
    /// Lawson RK4 steps per output interval when the plant is `rom` (≥ 1) (default 16).
    pub rom_plant_substeps: Option<usize>,
}

/// `[sweep]`: the runs of `flexmpc sweep` (every `omega0` × every controller, in parallel).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    /// Disturbance magnitudes `ω0` (rad/s, finite, non-empty). `--omega0` overrides.
    pub omega0: Vec<f64>,
    /// Controllers, each `nmpc` or `lmpc` (non-empty) [the `[controller] kind`].
    /// `--controller` overrides.
    pub controllers: Option<Vec<mpc::ControllerKind>>,
}

/// A whole scene.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// Free text.
    pub description: Option<String>,
    /// `planar` or `spatial`.
    pub components: ComponentsName,
    /// Allow disconnected structures (default false).
    #[serde(default)]
    pub allow_disconnected: bool,
    /// Named sections.
    pub sections: std::collections::BTreeMap<String, Spanned<SectionSpec>>,
    /// Beams.
    pub beams: Vec<Spanned<BeamSpec>>,
    /// Joints between beams.
    #[serde(default)]
    pub joints: Vec<Spanned<JointSpec>>,
    /// Supports to the ground.
    #[serde(default)]
    pub supports: Vec<Spanned<JointSpec>>,
    /// Gravity (global).
    pub gravity: Option<[f64; 3]>,
    /// Point loads.
    #[serde(default)]
    pub loads: Vec<Spanned<LoadSpec>>,
    /// Joint torques.
    #[serde(default)]
    pub torques: Vec<Spanned<TorqueSpec>>,
    /// Initial conditions.
    #[serde(default)]
    pub initial: InitialSpec,
    /// Run settings.
    pub run: Spanned<RunSpec>,
    /// Outputs.
    #[serde(default)]
    pub output: OutputSpec,
    /// Modes listed by `flexmpc modes` and the controller model's mode set.
    pub modes: Option<Spanned<ModesSpec>>,
    /// Controller of `flexmpc mpc`/`sweep`.
    pub controller: Option<Spanned<ControllerSpec>>,
    /// Closed-loop scenario of `flexmpc mpc`/`sweep` (needs `[modes]` with a mode set).
    pub scenario: Option<Spanned<ScenarioSpec>>,
    /// The runs of `flexmpc sweep`.
    pub sweep: Option<Spanned<SweepSpec>>,
    /// Commanded joint rotations of the closed loop (reconfiguration).
    pub reference: Option<Spanned<ReferenceSpec>>,
}

/// `[reference]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSpec {
    /// Commanded joint rotations, at most one per joint or support.
    pub joints: Vec<JointCommandSpec>,
}

/// One commanded rotation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointCommandSpec {
    /// Joint or support name.
    pub joint: String,
    /// Rotation axis (joint: first end frame; support: global).
    pub axis: [f64; 3],
    /// Target angle (deg).
    pub angle_deg: f64,
    /// Time to reach the target (s) \[0\].
    pub ramp_s: Option<f64>,
    /// Time the ramp starts (s) \[0\].
    pub start_s: Option<f64>,
}
