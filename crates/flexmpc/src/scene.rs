//! Scene files (TOML): sections, beams and meshes, joints, supports, loads and inputs,
//! initial conditions, run settings — parsed with serde and turned into a
//! [`multibody_constraints::Plant`]. Every error names the file, the line and the field.

use std::fmt;
use std::path::{Path, PathBuf};

use intrinsic_beam::rotation::axis_angle;
use intrinsic_beam::{Amplitude, Beam, Components, LoadFrame, Mesh, PointLoad, Section};
use multibody_constraints::{End, EndRef, Frame, Freedom, Joint, JointKind, Support};
use multibody_constraints::{Placement, Structure, StructureBeam, StructureSettings};
use multibody_constraints::{Plant, PlantSettings};
use nalgebra::{Matrix6, Vector3, Vector6};
use serde::Deserialize;
use toml::Spanned;

/// A scene error: file, line (1-based, when known), field path and message.
#[derive(Debug)]
pub struct SceneError {
    /// The scene file.
    pub file: PathBuf,
    /// Line of the offending entry (1-based), if known.
    pub line: Option<usize>,
    /// Field path, e.g. `joints[1].ends`.
    pub field: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => {
                write!(f, "{}:{}: field `{}`: {}", self.file.display(), l, self.field, self.message)
            }
            None => write!(f, "{}: field `{}`: {}", self.file.display(), self.field, self.message),
        }
    }
}

impl std::error::Error for SceneError {}

/// A section: a preset of the paper or explicit diagonals.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SectionSpec {
    /// `paper-2d` or `paper-3d` (theory.md §9), or absent for explicit values.
    pub preset: Option<String>,
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
    pub kind: String,
    /// Joints: the ends, `"beam:start"` / `"beam:end"` (at least 2).
    pub ends: Option<Vec<String>>,
    /// Supports: the end, `"beam:start"` / `"beam:end"`.
    pub end: Option<String>,
    /// Hinge axis.
    pub axis: Option<[f64; 3]>,
    /// Frame of the hinge axis / custom axes: `global`, `each-end`, or `end-N` (N-th end).
    pub frame: Option<String>,
    /// Custom: `rigid`/`free` per translation axis.
    pub translation: Option<[String; 3]>,
    /// Custom: `rigid`/`free` per rotation axis.
    pub rotation: Option<[String; 3]>,
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
    pub frame: String,
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

/// The paper's mode counts per kind (a `[modes] kinds = { .. }` table); absent kinds are 0.
#[derive(Debug, Deserialize, Clone, Copy, Default)]
#[serde(deny_unknown_fields)]
pub struct KindsSpec {
    /// Rigid-body modes (2D two-link: 2; 3D: 4).
    #[serde(default)]
    pub rigid: usize,
    /// Axial modes.
    #[serde(default)]
    pub axial: usize,
    /// Torsion modes.
    #[serde(default)]
    pub torsion: usize,
    /// Bending modes about e2 (the planar bending).
    #[serde(default)]
    pub bending_e2: usize,
    /// Bending modes about e3.
    #[serde(default)]
    pub bending_e3: usize,
    /// Mixed modes (axial and bending together, e.g. at 45°).
    #[serde(default)]
    pub mixed: usize,
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
    pub selection: Option<String>,
    /// Controller model: the lowest modes of each kind (counts, each ≥ 0, total ≥ 1).
    pub kinds: Option<KindsSpec>,
    /// Controller model: the lowest `n` modes (rigid first), n ≥ 1.
    pub lowest: Option<usize>,
    /// Controller model: explicit mode indices (0-based, basis order: rigid first, then by
    /// frequency), non-empty.
    pub indices: Option<Vec<usize>>,
}

/// `[controller.weights]`: the cost (34)–(36). Every field defaults to the paper's value
/// (§5.2; `mpc::MpcSettings`); any other value is a deliberate deviation.
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct WeightsSpec {
    /// `k_x1`, weight of the velocity coordinates `q1` (≥ 0) [0.01].
    pub kx1: Option<f64>,
    /// `k_x2`, weight of the strain coordinates `q2` (≥ 0) [0.01].
    pub kx2: Option<f64>,
    /// `k_Δξ`, weight of the quaternion jump across the joints (36) (≥ 0) (default 2).
    pub k_dxi: Option<f64>,
    /// `k_u`, `R = k_u I` (> 0) [0.1].
    pub ku: Option<f64>,
    /// `Kξ` entries of the shifting-equilibrium and rigid modes' quaternion modes (≥ 0) (default 1).
    pub k_xi_rigid: Option<f64>,
    /// `Kξ` entries of the elastic modes' quaternion modes (≥ 0) [0.01].
    pub k_xi_elastic: Option<f64>,
    /// Input bound `|u_i| ≤ u_max` (N or N·m, > 0) (default 5).
    pub u_max: Option<f64>,
}

/// `[controller]`: which MPC and its solver settings (the defaults are those of
/// `mpc::ControllerSettings`).
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ControllerSpec {
    /// `nmpc` (SQP on the augmented modal model) or `lmpc` (one QP on the model linearised
    /// at the reference) (default nmpc). `--controller` overrides.
    pub kind: Option<String>,
    /// One SQP iteration per sample from the shifted plan instead of iterating to the KKT
    /// tolerance [false].
    pub real_time_iteration: Option<bool>,
    /// Step of the NMPC's first attempt: `true` merit line search, `false` full Gauss–Newton
    /// step (default true).
    pub line_search: Option<bool>,
    /// SQP iteration limit per sample (≥ 1) (default 10).
    pub max_iterations: Option<usize>,
    /// KKT tolerance of the SQP (> 0) [1e-4].
    pub kkt_tolerance: Option<f64>,
    /// An iteration-limit plan is accepted when its shooting defects are at most this
    /// (> 0) [1e-2].
    pub accept_violation: Option<f64>,
    /// Levenberg–Marquardt term of the first SQP attempt (≥ 0) (default 0).
    pub levenberg_marquardt: Option<f64>,
    /// On failure, retry from the linear MPC plan with the paper's sub-relaxation [true].
    pub retry: Option<bool>,
    /// Sub-relaxation factor `α` of the retry, in (0, 1] [0.5].
    pub retry_relaxation: Option<f64>,
    /// Levenberg–Marquardt term of the retry (≥ 0) [1e-3].
    pub retry_levenberg_marquardt: Option<f64>,
    /// When every NMPC attempt fails, apply the linear MPC plan [true].
    pub fallback_to_lmpc: Option<bool>,
    /// Check each NMPC plan's predicted joint angles against `plan_joint_limit_deg` and treat
    /// a plan beyond it as a failed attempt [true].
    pub joint_limit: Option<bool>,
    /// Range of validity of the controller model for that check (deg, in (0, 180]) [20].
    pub plan_joint_limit_deg: Option<f64>,
    /// Integrator in each shooting interval: `lawson-rk4`, `rk4` or `implicit-midpoint`
    /// [lawson-rk4].
    pub integrator: Option<String>,
    /// Integrator substeps per shooting interval `τp/Nc` (≥ 1) (default 16).
    pub substeps: Option<usize>,
    /// Weights of the cost, the paper's by default.
    pub weights: Option<Spanned<WeightsSpec>>,
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
    /// Sampling time `τs` (s, in (0, horizon], a multiple of `output_interval`): each control
    /// is held for `τs` [0.2].
    pub sampling: Option<f64>,
    /// Prediction horizon `τp` (s, > 0) (default 6).
    pub horizon: Option<f64>,
    /// Number `Nc` of piecewise-constant control intervals over `τp` (≥ 1) (default 24).
    pub intervals: Option<usize>,
    /// Plant: `fe` (the constrained FE model, the paper's) or `rom` (the modal model
    /// itself, fast studies) (default fe). `--plant` overrides.
    pub plant: Option<String>,
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
    pub controllers: Option<Vec<String>>,
}

/// A whole scene.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// Free text.
    pub description: Option<String>,
    /// `planar` or `spatial`.
    pub components: String,
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
}

/// An input applied during the run (for the CSV).
#[derive(Debug, Clone)]
pub enum InputKind {
    /// Point load index on a beam.
    Load {
        /// Beam index.
        beam: usize,
        /// Index into the beam's point loads.
        index: usize,
    },
    /// Joint torque.
    Torque {
        /// Joint name.
        joint: String,
        /// Axis.
        axis: Option<usize>,
        /// Value.
        value: f64,
        /// History.
        amplitude: Amplitude,
    },
}

/// A named input.
#[derive(Debug, Clone)]
pub struct Input {
    /// Column name.
    pub name: String,
    /// What it drives.
    pub kind: InputKind,
}

/// A scene ready to run.
pub struct Scene {
    /// Source file.
    pub file: PathBuf,
    /// The plant, in its initial state.
    pub plant: Plant,
    /// Number of steps.
    pub steps: usize,
    /// Output stride.
    pub output_every: usize,
    /// Inputs (for the CSV and for torque histories).
    pub inputs: Vec<Input>,
    /// Plot columns.
    pub plot: Vec<String>,
    /// Plot title.
    pub title: String,
    /// Description.
    pub description: String,
    /// Scene name: the file stem (output folders are `out/<name>`).
    pub name: String,
    /// Modes listed and plotted by `flexmpc modes` and the report (`[modes] count`) (default 8).
    pub mode_count: usize,
    /// Reference angles (deg) for `flexmpc modes` (`[modes] angles`; empty: the scene's).
    pub mode_angles: Vec<f64>,
    /// The closed-loop setup (`[scenario]` present), for `flexmpc mpc`/`sweep`.
    pub control: Option<Control>,
}

/// What `flexmpc mpc` and `flexmpc sweep` run: an `mpc::Scenario` built from the scene
/// (structure, control inputs, mode set, disturbance, timing, weights) and the controller.
#[derive(Clone, Debug)]
pub struct Control {
    /// The scenario (structure and inputs from the scene; `name` = the scene's name).
    pub scenario: mpc::Scenario,
    /// Controller settings (`[controller]`).
    pub controller: mpc::ControllerSettings,
    /// Plant (`[scenario] plant`).
    pub plant: mpc::PlantKind,
    /// Disturbance magnitude of `flexmpc mpc` (`[scenario] omega0`).
    pub omega0: f64,
    /// `[sweep] omega0` (empty when the scene has no `[sweep]`).
    pub sweep_omegas: Vec<f64>,
    /// `[sweep] controllers` (default: the `[controller] kind`).
    pub sweep_controllers: Vec<mpc::ControllerKind>,
}

struct Ctx<'a> {
    file: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    fn line(&self, offset: usize) -> usize {
        self.text[..offset.min(self.text.len())].matches('\n').count() + 1
    }

    /// An error at the entry `span`; the line is that of the field's own `key = …` line
    /// inside the entry when there is one, else the entry's first line.
    fn err<T>(
        &self,
        span: Option<std::ops::Range<usize>>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Result<T, SceneError> {
        let field = field.into();
        let key = field
            .rsplit('.')
            .next()
            .unwrap_or("")
            .split('[')
            .next()
            .unwrap_or("")
            .trim()
            .to_string();
        let line = span.map(|s| {
            // The entry runs from its span to the next table header (spans of array-of-table
            // entries may cover the header only).
            let start = s.start.min(self.text.len());
            let first_nl =
                self.text[start..].find('\n').map(|i| start + i + 1).unwrap_or(self.text.len());
            let end = self.text[first_nl..]
                .match_indices('\n')
                .map(|(i, _)| first_nl + i + 1)
                .find(|&i| self.text[i..].trim_start_matches([' ', '\t']).starts_with('['))
                .unwrap_or(self.text.len())
                .max(s.end.min(self.text.len()));
            let body = &self.text[start..end];
            let mut off = s.start;
            for l in body.split_inclusive('\n') {
                let t = l.trim_start();
                if !key.is_empty()
                    && field.contains('.')
                    && t.starts_with(&key)
                    && t[key.len()..].trim_start().starts_with('=')
                {
                    return self.line(off);
                }
                off += l.len();
            }
            self.line(s.start)
        });
        // Top-level keys without a span: their own line.
        let line = line.or_else(|| {
            self.text
                .lines()
                .position(|l| {
                    let t = l.trim_start();
                    !field.contains('.')
                        && t.starts_with(field.as_str())
                        && t[field.len()..].trim_start().starts_with('=')
                })
                .map(|i| i + 1)
        });
        Err(SceneError { file: self.file.to_path_buf(), line, field, message: message.into() })
    }
}

/// Reads and parses a scene file (syntax and types), without building it.
pub fn parse(file: &Path) -> Result<(SceneSpec, String), SceneError> {
    let text = std::fs::read_to_string(file).map_err(|e| SceneError {
        file: file.to_path_buf(),
        line: None,
        field: "(file)".into(),
        message: format!("cannot read: {e}"),
    })?;
    parse_str(file, &text).map(|s| (s, text))
}

/// Parses scene text; `file` is used in errors.
pub fn parse_str(file: &Path, text: &str) -> Result<SceneSpec, SceneError> {
    toml::from_str::<SceneSpec>(text).map_err(|e| {
        let ctx = Ctx { file, text };
        let line = e.span().map(|s| ctx.line(s.start));
        // toml's message names the field (e.g. "missing field `dt`", "unknown field `lenght`").
        let message = e.message().trim().to_string();
        // "invalid type/value/length: … `-4` …" quote the value, not the field: take the key
        // at the span for those.
        let quotes_field = !message.starts_with("invalid");
        let field = field_from_message(&message)
            .filter(|_| quotes_field)
            .map(|f| match e.span().and_then(|s| table_at(text, s.start)) {
                Some(t) if !message.contains("missing") || !t.is_empty() => format!("{t}.{f}"),
                _ => f,
            })
            .or_else(|| e.span().map(|s| field_at(text, s.start)))
            .unwrap_or_else(|| "(syntax)".into());
        SceneError { file: file.to_path_buf(), line, field, message }
    })
}

/// The table path (e.g. `beams[1]`) in effect at byte `offset`.
fn table_at(text: &str, offset: usize) -> Option<String> {
    let mut current: Option<String> = None;
    let mut counts: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    let mut pos = 0;
    for line in text.split_inclusive('\n') {
        if pos > offset {
            break;
        }
        let t = line.trim();
        if let Some(name) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
            let c = counts.entry(name.trim().to_string()).or_insert(0);
            current = Some(format!("{}[{}]", name.trim(), *c));
            *c += 1;
        } else if let Some(name) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
            current = Some(name.trim().to_string());
        }
        pos += line.len();
    }
    current
}

/// The dotted field path (`table.key`) of the `key = value` line containing byte `offset`.
fn field_at(text: &str, offset: usize) -> String {
    let start = text[..offset.min(text.len())].rfind('\n').map(|i| i + 1).unwrap_or(0);
    let line = text[start..].lines().next().unwrap_or("");
    let key = line.split('=').next().unwrap_or("").trim().to_string();
    match (table_at(text, offset), key.is_empty() || !line.contains('=')) {
        (Some(t), false) => format!("{t}.{key}"),
        (None, false) => key,
        (Some(t), true) => t,
        (None, true) => "(syntax)".into(),
    }
}

fn field_from_message(m: &str) -> Option<String> {
    let start = m.find('`')?;
    let rest = &m[start + 1..];
    let end = rest.find('`')?;
    Some(rest[..end].to_string())
}

fn section_of(
    ctx: &Ctx<'_>,
    name: &str,
    spec: &Spanned<SectionSpec>,
) -> Result<Section, SceneError> {
    let span = Some(spec.span());
    let s = spec.get_ref();
    let field = |f: &str| format!("sections.{name}.{f}");
    let mut section = match (&s.preset, &s.mass, &s.stiffness) {
        (Some(p), None, None) => match p.as_str() {
            "paper-2d" => Section::paper_2d(),
            "paper-3d" => Section::paper_3d(),
            other => {
                return ctx.err(
                    span,
                    field("preset"),
                    format!("unknown preset `{other}` (allowed: paper-2d, paper-3d)"),
                )
            }
        },
        (None, Some(m), Some(k)) => {
            let f = s.stiffness_factor.unwrap_or(1.0);
            let k = k.map(|x| x * f);
            match Section::from_diagonals(*m, k) {
                Ok(sec) => sec,
                Err(e) => return ctx.err(span, field("mass/stiffness"), e.to_string()),
            }
        }
        (Some(_), _, _) => {
            return ctx.err(
                span,
                field("preset"),
                "give either `preset` or `mass` and `stiffness`, not both",
            )
        }
        _ => return ctx.err(
            span,
            field("mass"),
            "give `preset` (paper-2d, paper-3d) or both `mass` and `stiffness` (6 entries each)",
        ),
    };
    if s.preset.is_some() {
        if let Some(f) = s.stiffness_factor {
            if !(f.is_finite() && f > 0.0) {
                return ctx.err(
                    span,
                    field("stiffness_factor"),
                    format!("must be positive, got {f}"),
                );
            }
            section.compliance /= f;
        }
    }
    if s.undamped {
        section = section.undamped();
    }
    if let Some(d2) = s.d2 {
        let d = Matrix6::from_diagonal(&Vector6::from(d2));
        section = match section.clone().with_damping(section.d0, section.d1, d) {
            Ok(x) => x,
            Err(e) => return ctx.err(span, field("d2"), e.to_string()),
        };
    }
    if let Some(k0) = s.kappa0 {
        section = match section.with_kappa0(Vector3::from(k0)) {
            Ok(x) => x,
            Err(e) => return ctx.err(span, field("kappa0"), e.to_string()),
        };
    }
    Ok(section)
}

fn parse_end(
    ctx: &Ctx<'_>,
    span: std::ops::Range<usize>,
    field: &str,
    text: &str,
    beams: &[String],
) -> Result<EndRef, SceneError> {
    let Some((b, e)) = text.split_once(':') else {
        return ctx.err(
            Some(span),
            field,
            format!("`{text}` is not of the form \"beam:start\" or \"beam:end\""),
        );
    };
    if !beams.iter().any(|x| x == b) {
        return ctx.err(
            Some(span),
            field,
            format!("unknown beam `{b}` (beams: {})", beams.join(", ")),
        );
    }
    let end = match End::parse(field, e) {
        Ok(end) => end,
        Err(_) => {
            return ctx.err(Some(span), field, format!("unknown end `{e}` (allowed: start, end)"))
        }
    };
    Ok(EndRef::new(b, end))
}

fn parse_frame(
    ctx: &Ctx<'_>,
    span: std::ops::Range<usize>,
    field: &str,
    text: &str,
) -> Result<Frame, SceneError> {
    match text {
        "global" => Ok(Frame::Global),
        "each-end" => Ok(Frame::EachEnd),
        t if t.starts_with("end-") => match t[4..].parse::<usize>() {
            Ok(i) => Ok(Frame::End(i)),
            Err(_) => ctx.err(
                Some(span),
                field,
                format!("bad frame `{t}` (allowed: global, each-end, end-N)"),
            ),
        },
        t => ctx.err(
            Some(span),
            field,
            format!("unknown frame `{t}` (allowed: global, each-end, end-N)"),
        ),
    }
}

fn joint_kind(
    ctx: &Ctx<'_>,
    spec: &Spanned<JointSpec>,
    field: &str,
    support: bool,
) -> Result<JointKind, SceneError> {
    let span = spec.span();
    let j = spec.get_ref();
    let default_frame = if support { "global" } else { "end-0" };
    let frame = parse_frame(
        ctx,
        span.clone(),
        &format!("{field}.frame"),
        j.frame.as_deref().unwrap_or(default_frame),
    )?;
    let freedoms = |f: &Option<[String; 3]>, name: &str| -> Result<[Freedom; 3], SceneError> {
        let Some(f) = f else {
            return ctx.err(
                Some(span.clone()),
                format!("{field}.{name}"),
                "a custom joint needs 3 entries, each `rigid` or `free`",
            );
        };
        let mut out = [Freedom::Rigid; 3];
        for (i, x) in f.iter().enumerate() {
            out[i] = match x.as_str() {
                "rigid" => Freedom::Rigid,
                "free" => Freedom::Free,
                other => {
                    return ctx.err(
                        Some(span.clone()),
                        format!("{field}.{name}[{i}]"),
                        format!("`{other}` (allowed: rigid, free)"),
                    )
                }
            };
        }
        Ok(out)
    };
    Ok(match j.kind.as_str() {
        "weld" | "rigid" => JointKind::Weld,
        "ball" => JointKind::Ball,
        "universal" | "wheel" => JointKind::Universal,
        "hinge" => {
            let Some(axis) = j.axis else {
                return ctx.err(
                    Some(span),
                    format!("{field}.axis"),
                    "a hinge needs `axis = [x, y, z]`",
                );
            };
            JointKind::Hinge { axis, frame }
        }
        "custom" => {
            let rf = match &j.rotation_frame {
                Some(t) => parse_frame(ctx, span.clone(), &format!("{field}.rotation_frame"), t)?,
                None => frame,
            };
            JointKind::Custom {
                translation: freedoms(&j.translation, "translation")?,
                translation_frame: frame,
                rotation: freedoms(&j.rotation, "rotation")?,
                rotation_frame: rf,
                axes: j.axes,
            }
        }
        other => {
            return ctx.err(
                Some(span),
                format!("{field}.kind"),
                format!(
                    "unknown joint kind `{other}` (allowed: weld, ball, hinge, universal, custom)"
                ),
            )
        }
    })
}

fn amplitude(
    ctx: &Ctx<'_>,
    span: std::ops::Range<usize>,
    field: &str,
    a: &Option<AmplitudeSpec>,
) -> Result<Amplitude, SceneError> {
    let amp = match a {
        None => Amplitude::Constant,
        Some(AmplitudeSpec { ramp: Some(r), table: None }) => Amplitude::Ramp { duration: *r },
        Some(AmplitudeSpec { ramp: None, table: Some(t) }) => {
            Amplitude::Table(t.iter().map(|p| (p[0], p[1])).collect())
        }
        Some(_) => {
            return ctx.err(
                Some(span),
                field,
                "give exactly one of `ramp = seconds` or `table = [[t, a], …]`",
            )
        }
    };
    if let Err(e) = amp.validate(field) {
        return ctx.err(Some(span), field, e.to_string());
    }
    Ok(amp)
}

/// Builds a scene from a file.
pub fn load(file: &Path) -> Result<Scene, SceneError> {
    let (spec, text) = parse(file)?;
    build(file, &text, spec)
}

/// Builds a scene from a file with the reference angle of its first joint-attached beam
/// (the structure's first joint) replaced by `angle_deg`: `flexmpc modes --angle`.
pub fn load_at_angle(file: &Path, angle_deg: f64) -> Result<Scene, SceneError> {
    let (mut spec, text) = parse(file)?;
    let Some(attach) = spec.beams.iter_mut().find_map(|b| b.get_mut().attach.as_mut()) else {
        return Err(SceneError {
            file: file.to_path_buf(),
            line: None,
            field: "beams.attach".into(),
            message: "--angle needs a beam placed by a joint (`attach = { joint = .. }`); \
                      this scene has none"
                .into(),
        });
    };
    if !angle_deg.is_finite() {
        return Err(SceneError {
            file: file.to_path_buf(),
            line: None,
            field: "--angle".into(),
            message: format!("the angle must be finite, got {angle_deg}"),
        });
    }
    attach.angle_deg = angle_deg;
    build(file, &text, spec)
}

/// Builds a scene from text (`file` names it in errors).
pub fn load_str(file: &Path, text: &str) -> Result<Scene, SceneError> {
    let spec = parse_str(file, text)?;
    build(file, text, spec)
}

/// Largest mesh a scene may ask for, per beam: beyond it a step system needs gigabytes, and
/// no run of this library needs it (frequencies converge at second order, docs/intrinsic-beam.md).
pub const MAX_ELEMENTS_PER_BEAM: usize = 100_000;

fn build(file: &Path, text: &str, spec: SceneSpec) -> Result<Scene, SceneError> {
    let ctx = Ctx { file, text };
    let components = match spec.components.as_str() {
        "planar" => Components::Planar,
        "spatial" => Components::Spatial,
        other => {
            return ctx.err(None, "components", format!("`{other}` (allowed: planar, spatial)"))
        }
    };
    let mut sections = std::collections::BTreeMap::new();
    for (name, s) in &spec.sections {
        sections.insert(name.clone(), section_of(&ctx, name, s)?);
    }
    let beam_names: Vec<String> = spec.beams.iter().map(|b| b.get_ref().name.clone()).collect();
    let mut beams = Vec::new();
    for (i, b) in spec.beams.iter().enumerate() {
        let span = Some(b.span());
        let bs = b.get_ref();
        let f = |x: &str| format!("beams[{i}].{x}");
        let Some(section) = sections.get(&bs.section) else {
            let known: Vec<&str> = sections.keys().map(String::as_str).collect();
            return ctx.err(
                span,
                f("section"),
                format!("unknown section `{}` (sections: {})", bs.section, known.join(", ")),
            );
        };
        if !(bs.length.is_finite() && bs.length > 0.0) {
            return ctx.err(span, f("length"), format!("must be positive, got {}", bs.length));
        }
        if bs.elements == 0 {
            return ctx.err(span, f("elements"), "must be at least 1");
        }
        if bs.elements > MAX_ELEMENTS_PER_BEAM {
            return ctx.err(
                span,
                f("elements"),
                format!(
                    "at most {MAX_ELEMENTS_PER_BEAM} per beam (its step system would need gigabytes), got {}",
                    bs.elements
                ),
            );
        }
        let mesh = Mesh::uniform(bs.length, bs.elements)
            .or_else(|e| ctx.err(span.clone(), f("length"), e.to_string()))?;
        let beam = Beam::new(section.clone(), mesh, components)
            .or_else(|e| ctx.err(span.clone(), f("section"), e.to_string()))?;
        let placement = match (&bs.attach, bs.origin, bs.rotation) {
            (Some(a), None, None) => Placement::Attached {
                joint: a.joint.clone(),
                axis: a.axis,
                angle: a.angle_deg.to_radians(),
            },
            (None, o, r) => {
                let o = o.unwrap_or([0.0; 3]);
                if let Some(r) = &r {
                    let n = Vector3::from(r.axis).norm();
                    if !(n.is_finite() && n > 0.0 && r.angle_deg.is_finite()) {
                        return ctx.err(
                            span,
                            f("rotation"),
                            format!(
                                "axis must be finite and non-zero and angle_deg finite, got axis {:?}, angle_deg {}",
                                r.axis, r.angle_deg
                            ),
                        );
                    }
                }
                let q = r
                    .map(|r| axis_angle(&Vector3::from(r.axis), r.angle_deg.to_radians()))
                    .unwrap_or(nalgebra::Vector4::new(1.0, 0.0, 0.0, 0.0));
                Placement::At { origin: Vector3::from(o), quaternion: q }
            }
            _ => {
                return ctx.err(
                    span,
                    f("attach"),
                    "give either `attach` or `origin`/`rotation`, not both",
                )
            }
        };
        beams.push(StructureBeam::new(bs.name.clone(), beam, placement));
    }
    let mut joints = Vec::new();
    for (i, j) in spec.joints.iter().enumerate() {
        let field = format!("joints[{i}]");
        let js = j.get_ref();
        let Some(ends) = &js.ends else {
            return ctx.err(
                Some(j.span()),
                format!("{field}.ends"),
                "a joint needs `ends = [\"beam:end\", \"beam:start\", …]`",
            );
        };
        if js.end.is_some() {
            return ctx.err(
                Some(j.span()),
                format!("{field}.end"),
                "a joint takes `ends` (a list); `end` is for supports",
            );
        }
        let ends = ends
            .iter()
            .map(|e| parse_end(&ctx, j.span(), &format!("{field}.ends"), e, &beam_names))
            .collect::<Result<Vec<_>, _>>()?;
        joints.push(Joint {
            name: js.name.clone(),
            ends,
            kind: joint_kind(&ctx, j, &field, false)?,
        });
    }
    let mut supports = Vec::new();
    for (i, s) in spec.supports.iter().enumerate() {
        let field = format!("supports[{i}]");
        let ss = s.get_ref();
        let Some(end) = &ss.end else {
            return ctx.err(
                Some(s.span()),
                format!("{field}.end"),
                "a support needs `end = \"beam:start\"`",
            );
        };
        if ss.ends.is_some() {
            return ctx.err(
                Some(s.span()),
                format!("{field}.ends"),
                "a support takes one `end`; `ends` is for joints",
            );
        }
        let end = parse_end(&ctx, s.span(), &format!("{field}.end"), end, &beam_names)?;
        supports.push(Support {
            name: ss.name.clone(),
            end,
            kind: joint_kind(&ctx, s, &field, true)?,
        });
    }
    // Structure-level errors: attribute to the joint/support/beam they name.
    let structure = Structure::new(
        beams,
        joints,
        supports,
        StructureSettings { allow_disconnected: spec.allow_disconnected, ..Default::default() },
    )
    .or_else(|e| {
        let msg = e.to_string();
        let (span, field) = locate(&spec, &msg);
        ctx.err(span, field, msg)
    })?;
    let run = spec.run.get_ref();
    let run_span = Some(spec.run.span());
    if !(run.dt.is_finite() && run.dt > 0.0) {
        return ctx.err(run_span, "run.dt", format!("must be positive, got {}", run.dt));
    }
    if !(run.duration.is_finite() && run.duration >= 0.0) {
        return ctx.err(
            run_span,
            "run.duration",
            format!("must be non-negative, got {}", run.duration),
        );
    }
    let settings = PlantSettings {
        dt: run.dt,
        newton_tolerance: run.newton_tolerance.unwrap_or(1e-12),
        ..Default::default()
    };
    let mut plant = Plant::new(structure, settings).or_else(|e| {
        let msg = e.to_string();
        let (span, field) = locate(&spec, &msg);
        ctx.err(
            span.or(run_span.clone()),
            if field == "(structure)" { "run".to_string() } else { field },
            msg,
        )
    })?;
    if let Some(g) = spec.gravity {
        plant.set_gravity(Vector3::from(g)).or_else(|e| ctx.err(None, "gravity", e.to_string()))?;
    }
    let mut inputs = Vec::new();
    let mut controls = Vec::new();
    for (i, l) in spec.loads.iter().enumerate() {
        let span = l.span();
        let ls = l.get_ref();
        let f = |x: &str| format!("loads[{i}].{x}");
        let Some(b) = plant.structure().beam_index(&ls.beam) else {
            return ctx.err(
                Some(span),
                f("beam"),
                format!("unknown beam `{}` (beams: {})", ls.beam, beam_names.join(", ")),
            );
        };
        let n_el = plant.structure().beams()[b].beam.n_elements();
        let node = match &ls.node {
            NodeSpec::Index(n) if *n <= n_el => *n,
            NodeSpec::Index(n) => {
                return ctx.err(
                    Some(span),
                    f("node"),
                    format!("node {n} does not exist (beam `{}` has nodes 0..={n_el})", ls.beam),
                )
            }
            NodeSpec::Named(s) if s == "start" => 0,
            NodeSpec::Named(s) if s == "end" => n_el,
            NodeSpec::Named(s) => {
                return ctx.err(
                    Some(span),
                    f("node"),
                    format!("`{s}` (allowed: an index 0..={n_el}, start, end)"),
                )
            }
        };
        let frame = match ls.frame.as_str() {
            "follower" => LoadFrame::Follower,
            "dead" => LoadFrame::Dead,
            other => {
                return ctx.err(
                    Some(span),
                    f("frame"),
                    format!("`{other}` (allowed: follower, dead)"),
                )
            }
        };
        let fo = ls.force.unwrap_or([0.0; 3]);
        let mo = ls.moment.unwrap_or([0.0; 3]);
        let mut value = Vector6::new(fo[0], fo[1], fo[2], mo[0], mo[1], mo[2]);
        if value.iter().any(|v| !v.is_finite()) {
            return ctx.err(Some(span), f("force"), "entries must be finite");
        }
        let name = ls.name.clone().unwrap_or_else(|| format!("load{i}"));
        if ls.control {
            if frame != LoadFrame::Follower {
                return ctx.err(
                    Some(span),
                    f("frame"),
                    "a control load (`control = true`) must be `follower`",
                );
            }
            if ls.amplitude.is_some() {
                return ctx.err(
                    Some(span),
                    f("amplitude"),
                    "a control load has no `amplitude` (the controller sets its history)",
                );
            }
            if value.norm() == 0.0 {
                return ctx.err(
                    Some(span),
                    f("force"),
                    "a control load needs a non-zero unit load (`force` and/or `moment`), \
                     e.g. force = [1.0, 0.0, 0.0]",
                );
            }
            controls.push((
                span.start,
                mpc::ControlInput::Follower {
                    name: name.clone(),
                    beam: b,
                    node,
                    load: [value[0], value[1], value[2], value[3], value[4], value[5]],
                },
            ));
            value = Vector6::zeros();
        } else if spec.scenario.is_some() {
            return ctx.err(
                Some(span),
                f("control"),
                "a scene with [scenario] takes only control inputs: set `control = true` \
                 (the load is then a unit load scaled by the controller) or remove the load",
            );
        }
        let amp = amplitude(&ctx, span.clone(), &f("amplitude"), &ls.amplitude)?;
        let index = plant.loads(b).point.len();
        plant.loads_mut(b).point.push(PointLoad { node, frame, value, amplitude: amp });
        inputs.push(Input { name, kind: InputKind::Load { beam: b, index } });
    }
    for (i, t) in spec.torques.iter().enumerate() {
        let span = t.span();
        let ts = t.get_ref();
        let f = |x: &str| format!("torques[{i}].{x}");
        let amp = amplitude(&ctx, span.clone(), &f("amplitude"), &ts.amplitude)?;
        let mut value = ts.value;
        if ts.control {
            if ts.value != 1.0 {
                return ctx.err(
                    Some(span),
                    f("value"),
                    format!(
                        "a control torque's `value` is its unit and must be 1, got {} \
                         (the controller sets the torque)",
                        ts.value
                    ),
                );
            }
            if ts.amplitude.is_some() {
                return ctx.err(
                    Some(span),
                    f("amplitude"),
                    "a control torque has no `amplitude` (the controller sets its history)",
                );
            }
            value = 0.0;
            controls.push((
                span.start,
                mpc::ControlInput::JointTorque {
                    name: format!("torque:{}", ts.joint),
                    joint: ts.joint.clone(),
                    axis: ts.axis,
                },
            ));
        } else if spec.scenario.is_some() {
            return ctx.err(
                Some(span),
                f("control"),
                "a scene with [scenario] takes only control inputs: set `control = true` \
                 (the controller then sets the torque) or remove the torque",
            );
        }
        if !value.is_finite() {
            return ctx.err(Some(span), f("value"), format!("must be finite, got {value}"));
        }
        plant
            .set_joint_torque(&ts.joint, ts.axis, value * amp.at(0.0))
            .or_else(|e| ctx.err(Some(span.clone()), f("joint"), e.to_string()))?;
        inputs.push(Input {
            name: format!("torque:{}", ts.joint),
            kind: InputKind::Torque {
                joint: ts.joint.clone(),
                axis: ts.axis,
                value,
                amplitude: amp,
            },
        });
    }
    // Initial state.
    if !spec.initial.rigid.is_empty() {
        let s = plant.structure();
        let mut x = vec![0.0; s.dim()];
        for (i, r) in spec.initial.rigid.iter().enumerate() {
            let rs = r.get_ref();
            let full = s.rigid_rotation_state(
                Vector3::from(rs.omega),
                Vector3::from(rs.center.unwrap_or([0.0; 3])),
            );
            let targets: Vec<usize> = match &rs.beams {
                None => (0..s.beams().len()).collect(),
                Some(names) => {
                    let mut v = Vec::new();
                    for n in names {
                        match s.beam_index(n) {
                            Some(b) => v.push(b),
                            None => {
                                return ctx.err(
                                    Some(r.span()),
                                    format!("initial.rigid[{i}].beams"),
                                    format!("unknown beam `{n}`"),
                                )
                            }
                        }
                    }
                    v
                }
            };
            for b in targets {
                let (o, d) = (s.offset(b), s.beams()[b].beam.dim());
                x[o..o + d].copy_from_slice(&full[o..o + d]);
            }
        }
        plant.set_state(&x).or_else(|e| ctx.err(None, "initial", e.to_string()))?;
    }
    // Finite inputs can still overflow: a rate or a gravity near 1e308 squares to infinity.
    let (kinetic, potential) = (plant.energy(), plant.potential_energy());
    if !kinetic.is_finite() {
        return ctx.err(
            spec.initial.rigid.first().map(|r| r.span()),
            "initial.rigid",
            format!("the initial state's energy is not finite ({kinetic}): rates too large"),
        );
    }
    if !potential.is_finite() {
        return ctx.err(
            None,
            "gravity",
            format!("the potential energy is not finite ({potential}): gravity or loads too large"),
        );
    }
    let steps = (run.duration / run.dt).round() as usize;
    let output_every = run.output_every.unwrap_or(10);
    if output_every == 0 {
        return ctx.err(run_span, "run.output_every", "must be at least 1");
    }
    let name =
        file.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "scene".into());
    let (mode_count, mode_angles) = modes_of(&ctx, &spec)?;
    // control inputs in the order they appear in the file
    controls.sort_by_key(|(at, _)| *at);
    let controls = controls.into_iter().map(|(_, c)| c).collect();
    let control = control_of(&ctx, &spec, &plant, controls, &name)?;
    Ok(Scene {
        file: file.to_path_buf(),
        plant,
        steps,
        output_every,
        inputs,
        plot: spec.output.plot.clone(),
        title: spec.output.title.clone().unwrap_or_default(),
        description: spec.description.clone().unwrap_or_default(),
        name,
        mode_count,
        mode_angles,
        control,
    })
}

/// `[modes] count` and `angles`, checked.
fn modes_of(ctx: &Ctx<'_>, spec: &SceneSpec) -> Result<(usize, Vec<f64>), SceneError> {
    let Some(m) = &spec.modes else { return Ok((8, Vec::new())) };
    let span = Some(m.span());
    let ms = m.get_ref();
    let count = ms.count.unwrap_or(8);
    if count == 0 {
        return ctx.err(span, "modes.count", "must be at least 1");
    }
    let angles = ms.angles.clone().unwrap_or_default();
    if let Some(a) = angles.iter().find(|a| !a.is_finite()) {
        return ctx.err(span, "modes.angles", format!("angles (deg) must be finite, got {a}"));
    }
    if ms.angles.as_ref().is_some_and(|a| a.is_empty()) {
        return ctx.err(span, "modes.angles", "give at least one angle (deg), e.g. [0, 45, 90]");
    }
    if !angles.is_empty() && !spec.beams.iter().any(|b| b.get_ref().attach.is_some()) {
        return ctx.err(
            span,
            "modes.angles",
            "reference angles need a beam placed by a joint (`attach = { joint = .. }`)",
        );
    }
    Ok((count, angles))
}

/// The controller model's mode set of `[modes]` (exactly one of its four forms).
fn selection_of(ctx: &Ctx<'_>, spec: &SceneSpec) -> Result<modal_rom::ModeSelection, SceneError> {
    use modal_rom::{KindCounts, ModeSelection};
    const NEED: &str = "the controller model needs a mode set in [modes]: one of \
                        `selection = \"paper-2d\"|\"paper-3d\"`, `kinds = { rigid = 2, axial = 4, \
                        bending_e2 = 4 }`, `lowest = n` or `indices = [..]`";
    let Some(m) = &spec.modes else {
        let span = spec.scenario.as_ref().map(|s| s.span());
        return ctx.err(span, "modes", NEED);
    };
    let span = Some(m.span());
    let ms = m.get_ref();
    let given =
        [ms.selection.is_some(), ms.kinds.is_some(), ms.lowest.is_some(), ms.indices.is_some()];
    match given.iter().filter(|g| **g).count() {
        0 => return ctx.err(span, "modes.selection", NEED),
        1 => {}
        _ => {
            return ctx.err(
                span,
                "modes.selection",
                "give only one of `selection`, `kinds`, `lowest`, `indices`",
            )
        }
    }
    if let Some(p) = &ms.selection {
        return match p.as_str() {
            "paper-2d" => Ok(modal_rom::samples::paper_2d_selection()),
            "paper-3d" => Ok(modal_rom::samples::paper_3d_selection()),
            other => ctx.err(
                span,
                "modes.selection",
                format!("unknown mode set `{other}` (allowed: paper-2d, paper-3d)"),
            ),
        };
    }
    if let Some(k) = ms.kinds {
        let total = k.rigid + k.axial + k.torsion + k.bending_e2 + k.bending_e3 + k.mixed;
        if total == 0 {
            return ctx.err(span, "modes.kinds", "select at least one mode");
        }
        return Ok(ModeSelection::ByKind(KindCounts {
            rigid: k.rigid,
            axial: k.axial,
            torsion: k.torsion,
            bending_e2: k.bending_e2,
            bending_e3: k.bending_e3,
            mixed: k.mixed,
        }));
    }
    if let Some(n) = ms.lowest {
        if n == 0 {
            return ctx.err(span, "modes.lowest", "must be at least 1");
        }
        return Ok(ModeSelection::Lowest(n));
    }
    match &ms.indices {
        Some(v) if !v.is_empty() => Ok(ModeSelection::Indices(v.clone())),
        _ => ctx.err(span, "modes.indices", "give at least one mode index"),
    }
}

/// A positive finite value, or an error naming `field`.
fn positive(
    ctx: &Ctx<'_>,
    span: Option<std::ops::Range<usize>>,
    field: &str,
    v: f64,
) -> Result<f64, SceneError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        ctx.err(span, field, format!("must be finite and > 0, got {v}"))
    }
}

/// A finite value ≥ 0, or an error naming `field`.
fn non_negative(
    ctx: &Ctx<'_>,
    span: Option<std::ops::Range<usize>>,
    field: &str,
    v: f64,
) -> Result<f64, SceneError> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        ctx.err(span, field, format!("must be finite and ≥ 0, got {v}"))
    }
}

/// An optional `[controller]` value in `(0, max]` behind an on/off switch (`retry` /
/// `retry_relaxation`, `joint_limit` / `plan_joint_limit_deg`): `None` when neither is given
/// (keep the default), `Some(None)` when switched off, `Some(Some(v))` for a value; a value
/// given with the switch off is an error naming both.
fn switched(
    ctx: &Ctx<'_>,
    span: Option<std::ops::Range<usize>>,
    (switch, on): (&str, Option<bool>),
    field: &str,
    value: Option<f64>,
    max: f64,
) -> Result<Option<Option<f64>>, SceneError> {
    let key = format!("controller.{field}");
    match (on, value) {
        (Some(false), Some(_)) => {
            ctx.err(span, &key, format!("is unused with `{switch} = false`; remove one of them"))
        }
        (Some(false), None) => Ok(Some(None)),
        (_, Some(v)) if v > 0.0 && v <= max => Ok(Some(Some(v))),
        (_, Some(v)) => ctx.err(span, &key, format!("must be in (0, {max}], got {v}")),
        (_, None) => Ok(None),
    }
}

/// `nmpc` / `lmpc`.
pub fn controller_kind(name: &str) -> Option<mpc::ControllerKind> {
    match name {
        "nmpc" => Some(mpc::ControllerKind::Nmpc),
        "lmpc" => Some(mpc::ControllerKind::Lmpc),
        _ => None,
    }
}

/// `fe` / `rom`.
pub fn plant_kind(name: &str) -> Option<mpc::PlantKind> {
    match name {
        "fe" => Some(mpc::PlantKind::Fe),
        "rom" => Some(mpc::PlantKind::Rom),
        _ => None,
    }
}

/// `[controller]` → `mpc::ControllerSettings` and the weights part of `mpc::MpcSettings`.
fn controller_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    mpc_settings: &mut mpc::MpcSettings,
) -> Result<mpc::ControllerSettings, SceneError> {
    use ocp_transcription::IntegratorKind;
    let mut c = mpc::ControllerSettings::default();
    let Some(cs) = &spec.controller else { return Ok(c) };
    let span = Some(cs.span());
    let sp = || span.clone();
    let cs = cs.get_ref();
    if let Some(k) = &cs.kind {
        c.kind = match controller_kind(k) {
            Some(k) => k,
            None => {
                return ctx.err(sp(), "controller.kind", format!("`{k}` (allowed: nmpc, lmpc)"))
            }
        };
    }
    if let Some(v) = cs.real_time_iteration {
        c.real_time_iteration = v;
    }
    if let Some(v) = cs.line_search {
        c.globalisation = if v {
            ocp_transcription::Globalisation::merit()
        } else {
            ocp_transcription::Globalisation::FullStep
        };
    }
    if let Some(n) = cs.max_iterations {
        if n == 0 {
            return ctx.err(sp(), "controller.max_iterations", "must be at least 1");
        }
        c.max_iterations = n;
    }
    if let Some(v) = cs.kkt_tolerance {
        c.kkt_tolerance = positive(ctx, sp(), "controller.kkt_tolerance", v)?;
    }
    if let Some(v) = cs.accept_violation {
        c.accept_violation = positive(ctx, sp(), "controller.accept_violation", v)?;
    }
    if let Some(v) = cs.levenberg_marquardt {
        c.levenberg_marquardt = non_negative(ctx, sp(), "controller.levenberg_marquardt", v)?;
    }
    if let Some(v) = cs.retry_levenberg_marquardt {
        c.retry_levenberg_marquardt =
            non_negative(ctx, sp(), "controller.retry_levenberg_marquardt", v)?;
    }
    if let Some(a) =
        switched(ctx, sp(), ("retry", cs.retry), "retry_relaxation", cs.retry_relaxation, 1.0)?
    {
        c.retry_relaxation = a;
    }
    if let Some(v) = cs.fallback_to_lmpc {
        c.fallback_to_lmpc = v;
    }
    if let Some(d) = switched(
        ctx,
        sp(),
        ("joint_limit", cs.joint_limit),
        "plan_joint_limit_deg",
        cs.plan_joint_limit_deg,
        180.0,
    )? {
        c.plan_joint_limit_deg = d;
    }
    if let Some(i) = &cs.integrator {
        c.integrator.kind = match i.as_str() {
            "lawson-rk4" => IntegratorKind::LawsonRk4,
            "rk4" => IntegratorKind::Rk4,
            "implicit-midpoint" => IntegratorKind::ImplicitMidpoint,
            other => {
                return ctx.err(
                    sp(),
                    "controller.integrator",
                    format!("`{other}` (allowed: lawson-rk4, rk4, implicit-midpoint)"),
                )
            }
        };
    }
    if let Some(n) = cs.substeps {
        if n == 0 {
            return ctx.err(sp(), "controller.substeps", "must be at least 1");
        }
        c.integrator.substeps = n;
    }
    if let Some(w) = &cs.weights {
        let span = Some(w.span());
        let w = w.get_ref();
        let m = mpc_settings;
        for (name, v, slot) in [
            ("kx1", w.kx1, &mut m.kx1),
            ("kx2", w.kx2, &mut m.kx2),
            ("k_dxi", w.k_dxi, &mut m.k_dxi),
            ("k_xi_rigid", w.k_xi_rigid, &mut m.k_xi_rigid),
            ("k_xi_elastic", w.k_xi_elastic, &mut m.k_xi_elastic),
        ] {
            if let Some(v) = v {
                *slot = non_negative(ctx, span.clone(), &format!("controller.weights.{name}"), v)?;
            }
        }
        if let Some(v) = w.ku {
            m.ku = positive(ctx, span.clone(), "controller.weights.ku", v)?;
        }
        if let Some(v) = w.u_max {
            m.u_max = positive(ctx, span.clone(), "controller.weights.u_max", v)?;
        }
    }
    if let Err(e) = c.validate() {
        return ctx.err(sp(), "controller", e.to_string());
    }
    Ok(c)
}

/// `[scenario]`, `[controller]`, `[sweep]` and the mode set → the closed-loop setup.
fn control_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    plant: &Plant,
    controls: Vec<mpc::ControlInput>,
    name: &str,
) -> Result<Option<Control>, SceneError> {
    let Some(sc) = &spec.scenario else {
        for (what, present, span) in [
            ("controller", spec.controller.is_some(), spec.controller.as_ref().map(|c| c.span())),
            ("sweep", spec.sweep.is_some(), spec.sweep.as_ref().map(|c| c.span())),
        ] {
            if present {
                return ctx.err(
                    span,
                    what,
                    format!("[{what}] needs a [scenario] section (axis, omega0, …)"),
                );
            }
        }
        return Ok(None);
    };
    let span = Some(sc.span());
    let sp = || span.clone();
    let ss = sc.get_ref();
    if spec.gravity.is_some() {
        return ctx.err(
            None,
            "gravity",
            "a scene with [scenario] has no gravity (the closed loop's plant has none)",
        );
    }
    if controls.is_empty() {
        return ctx.err(
            sp(),
            "scenario",
            "a closed loop needs control inputs: mark [[loads]] or [[torques]] with \
             `control = true`",
        );
    }
    let selection = selection_of(ctx, spec)?;
    let mut m = mpc::MpcSettings::default();
    if let Some(v) = ss.horizon {
        m.horizon = positive(ctx, sp(), "scenario.horizon", v)?;
    }
    if let Some(v) = ss.sampling {
        m.sampling = positive(ctx, sp(), "scenario.sampling", v)?;
        if m.sampling > m.horizon {
            return ctx.err(
                sp(),
                "scenario.sampling",
                format!("τs = {} must not exceed the horizon τp = {}", m.sampling, m.horizon),
            );
        }
    }
    if let Some(n) = ss.intervals {
        if n == 0 {
            return ctx.err(sp(), "scenario.intervals", "must be at least 1");
        }
        m.intervals = n;
    }
    let controller = controller_of(ctx, spec, &mut m)?;
    let omega0 = ss.omega0.unwrap_or(1.0);
    if !omega0.is_finite() {
        return ctx.err(sp(), "scenario.omega0", format!("must be finite, got {omega0}"));
    }
    if ss.axis.iter().any(|v| !v.is_finite()) || ss.axis.iter().all(|v| *v == 0.0) {
        return ctx.err(
            sp(),
            "scenario.axis",
            format!("must be finite and non-zero, got {:?}", ss.axis),
        );
    }
    let center = ss.center.unwrap_or([0.0; 3]);
    if center.iter().any(|v| !v.is_finite()) {
        return ctx.err(sp(), "scenario.center", "entries must be finite");
    }
    let structure = plant.structure().clone();
    let supports: Vec<String> =
        structure.joints().iter().filter(|j| j.ground).map(|j| j.name.clone()).collect();
    let root = match &ss.root {
        Some(r) if supports.contains(r) => r.clone(),
        Some(r) => {
            return ctx.err(
                sp(),
                "scenario.root",
                format!("unknown support `{r}` (supports: {})", supports.join(", ")),
            )
        }
        None => match supports.first() {
            Some(r) => r.clone(),
            None => return ctx.err(sp(), "scenario.root", "the structure has no support"),
        },
    };
    let plant_kind = match ss.plant.as_deref() {
        None => mpc::PlantKind::Fe,
        Some(p) => match plant_kind(p) {
            Some(k) => k,
            None => return ctx.err(sp(), "scenario.plant", format!("`{p}` (allowed: fe, rom)")),
        },
    };
    let duration = positive(ctx, sp(), "scenario.duration", ss.duration.unwrap_or(7.5))?;
    let output_interval =
        positive(ctx, sp(), "scenario.output_interval", ss.output_interval.unwrap_or(0.05))?;
    let snapshot_interval =
        positive(ctx, sp(), "scenario.snapshot_interval", ss.snapshot_interval.unwrap_or(0.25))?;
    let rom_plant_substeps = ss.rom_plant_substeps.unwrap_or(16);
    if rom_plant_substeps == 0 {
        return ctx.err(sp(), "scenario.rom_plant_substeps", "must be at least 1");
    }
    let whole = |a: f64, b: f64| {
        let r = a / b;
        r.round() >= 1.0 && (r - r.round()).abs() <= 1e-9 * r.round()
    };
    let dt = plant.settings().dt;
    for (field, a, b, what) in [
        ("scenario.duration", duration, output_interval, "output_interval"),
        ("scenario.sampling", m.sampling, output_interval, "output_interval"),
        ("scenario.snapshot_interval", snapshot_interval, output_interval, "output_interval"),
        ("scenario.output_interval", output_interval, dt, "[run] dt"),
    ] {
        if !whole(a, b) {
            return ctx.err(
                sp(),
                field,
                format!("{a} s must be a whole multiple (≥ 1) of {what} = {b} s"),
            );
        }
    }
    let scenario = mpc::Scenario {
        name: name.to_string(),
        structure,
        inputs: controls,
        selection,
        rom_options: modal_rom::RomOptions::default(),
        omega_direction: ss.axis,
        center,
        root,
        duration,
        output_interval,
        snapshot_interval,
        plant: *plant.settings(),
        rom_plant_substeps,
        mpc: m,
    };
    if let Err(e) = scenario.validate() {
        return ctx.err(sp(), "scenario", e.to_string());
    }
    let (sweep_omegas, sweep_controllers) = match &spec.sweep {
        None => (Vec::new(), vec![controller.kind]),
        Some(sw) => {
            let span = Some(sw.span());
            let s = sw.get_ref();
            if s.omega0.is_empty() {
                return ctx.err(span, "sweep.omega0", "give at least one ω0 (rad/s)");
            }
            if let Some(w) = s.omega0.iter().find(|w| !w.is_finite()) {
                return ctx.err(span, "sweep.omega0", format!("must be finite, got {w}"));
            }
            let kinds = match &s.controllers {
                None => vec![controller.kind],
                Some(v) if v.is_empty() => {
                    return ctx.err(span, "sweep.controllers", "give at least one of nmpc, lmpc")
                }
                Some(v) => {
                    let mut out = Vec::new();
                    for k in v {
                        match controller_kind(k) {
                            Some(k) => out.push(k),
                            None => {
                                return ctx.err(
                                    span,
                                    "sweep.controllers",
                                    format!("`{k}` (allowed: nmpc, lmpc)"),
                                )
                            }
                        }
                    }
                    out
                }
            };
            (s.omega0.clone(), kinds)
        }
    };
    Ok(Some(Control {
        scenario,
        controller,
        plant: plant_kind,
        omega0,
        sweep_omegas,
        sweep_controllers,
    }))
}

/// The entry (span and field) that a structure error message names, by joint/support/beam
/// name in backquotes.
fn locate(spec: &SceneSpec, msg: &str) -> (Option<std::ops::Range<usize>>, String) {
    let quoted: Vec<&str> = msg.split('`').skip(1).step_by(2).collect();
    // Joints and supports first (the last one named is the one that clashed), then beams.
    for q in quoted.iter().rev() {
        for (i, j) in spec.joints.iter().enumerate() {
            if j.get_ref().name == *q {
                return (Some(j.span()), format!("joints[{i}] (`{q}`)"));
            }
        }
        for (i, s) in spec.supports.iter().enumerate() {
            if s.get_ref().name == *q {
                return (Some(s.span()), format!("supports[{i}] (`{q}`)"));
            }
        }
    }
    for q in &quoted {
        for (i, b) in spec.beams.iter().enumerate() {
            if b.get_ref().name == *q {
                let field = if msg.contains("placement") && b.get_ref().attach.is_some() {
                    format!("beams[{i}].attach")
                } else {
                    format!("beams[{i}] (`{q}`)")
                };
                return (Some(b.span()), field);
            }
        }
    }
    (None, "(structure)".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = r#"description = "test"
components = "planar"

[sections.link]
preset = "paper-2d"

[[beams]]
name = "link1"
section = "link"
length = 1.0
elements = 4

[[beams]]
name = "link2"
section = "link"
length = 1.0
elements = 4
attach = { joint = "elbow", axis = [0.0, 1.0, 0.0], angle_deg = 30.0 }

[[joints]]
name = "elbow"
kind = "hinge"
ends = ["link1:end", "link2:start"]
axis = [0.0, 1.0, 0.0]

[[supports]]
name = "root"
end = "link1:start"
kind = "hinge"
axis = [0.0, 1.0, 0.0]

[[loads]]
beam = "link2"
node = "end"
frame = "follower"
force = [0.0, 0.0, 0.1]

[run]
dt = 1e-3
duration = 0.01
"#;

    fn line_of(text: &str, needle: &str) -> usize {
        text.lines().position(|l| l.contains(needle)).expect("needle in text") + 1
    }

    /// Replaces `from` by `to` in the base scene, loads it, and checks that the error names
    /// the file, the expected line (of `at`, in the modified text) and `field`.
    fn expect_error(from: &str, to: &str, at: &str, field: &str) {
        assert!(BASE.contains(from), "base lacks {from}");
        let text = BASE.replacen(from, to, 1);
        let err = match load_str(Path::new("bad.toml"), &text) {
            Ok(_) => panic!("`{to}` was accepted"),
            Err(e) => e,
        };
        let msg = err.to_string();
        let line = line_of(&text, at);
        assert!(msg.starts_with(&format!("bad.toml:{line}:")), "expected line {line} in: {msg}");
        assert!(msg.contains(field), "expected field `{field}` in: {msg}");
    }

    #[test]
    fn base_scene_builds_and_runs() {
        let mut s = load_str(Path::new("ok.toml"), BASE).unwrap();
        assert_eq!(s.steps, 10);
        for _ in 0..s.steps {
            s.plant.step().unwrap();
        }
        assert!((s.plant.joint_angles()[0] - 30f64.to_radians()).abs() < 0.01);
    }

    #[test]
    fn malformed_scenes_name_file_line_and_field() {
        let l2 = "length = 1.0\nelements = 4\nattach";
        let elbow_ends = "ends = [\"link1:end\", \"link2:start\"]\naxis = [0.0, 1.0, 0.0]";
        // wrong type
        expect_error(
            "length = 1.0\nelements = 4\n\n[[beams]]",
            "length = \"one\"\nelements = 4\n\n[[beams]]",
            "length = \"one\"",
            "beams[0].length",
        );
        // unknown field (typo)
        expect_error("elements = 4\nattach", "elemnts = 4\nattach", "elemnts", "elemnts");
        // a beam rotation about a zero axis
        expect_error(
            "elements = 4\n\n[[beams]]",
            "elements = 4\nrotation = { axis = [0.0, 0.0, 0.0], angle_deg = 10.0 }\n\n[[beams]]",
            "rotation = {",
            "beams[0].rotation",
        );
        // a mesh too large to allocate
        expect_error(
            "elements = 4\nattach",
            "elements = 1000000\nattach",
            "elements = 1000000",
            "beams[1].elements",
        );
        // finite rates whose energy overflows
        expect_error(
            "[run]",
            "[[initial.rigid]]\nomega = [0.0, 1e200, 0.0]\n\n[run]",
            "[[initial.rigid]]",
            "initial.rigid",
        );
        // missing field
        expect_error("dt = 1e-3\n", "", "[run]", "dt");
        // unknown beam in a joint
        expect_error(
            "ends = [\"link1:end\", \"link2:start\"]",
            "ends = [\"link1:end\", \"link3:start\"]",
            "link3",
            "joints[0].ends",
        );
        // unknown end
        expect_error(
            "end = \"link1:start\"",
            "end = \"link1:middle\"",
            "link1:middle",
            "supports[0].end",
        );
        // negative length
        expect_error(l2, "length = -1.0\nelements = 4\nattach", "length = -1.0", "beams[1].length");
        // zero elements
        expect_error(l2, "length = 1.0\nelements = 0\nattach", "elements = 0", "beams[1].elements");
        // bad joint kind
        expect_error(
            "kind = \"hinge\"\nends",
            "kind = \"slider\"\nends",
            "kind = \"slider\"",
            "joints[0].kind",
        );
        // hinge without axis
        expect_error(
            elbow_ends,
            "ends = [\"link1:end\", \"link2:start\"]",
            "[[joints]]",
            "joints[0].axis",
        );
        // zero-length axis (found by the structure, attributed to the joint)
        expect_error(
            elbow_ends,
            "ends = [\"link1:end\", \"link2:start\"]\naxis = [0.0, 0.0, 0.0]",
            "[[joints]]",
            "joints[0]",
        );
        // planar hinge off e2
        expect_error(
            "kind = \"hinge\"\naxis = [0.0, 1.0, 0.0]\n\n[[loads]]",
            "kind = \"hinge\"\naxis = [1.0, 0.0, 0.0]\n\n[[loads]]",
            "[[supports]]",
            "supports[0]",
        );
        // end used twice
        expect_error("end = \"link1:start\"", "end = \"link1:end\"", "[[supports]]", "supports[0]");
        // unknown section
        expect_error(
            "section = \"link\"\nlength = 1.0\nelements = 4\nattach",
            "section = \"rod\"\nlength = 1.0\nelements = 4\nattach",
            "section = \"rod\"",
            "beams[1].section",
        );
        // bad preset
        expect_error(
            "preset = \"paper-2d\"",
            "preset = \"paper-4d\"",
            "paper-4d",
            "sections.link.preset",
        );
        // load on a node that does not exist
        expect_error("node = \"end\"", "node = 9", "node = 9", "loads[0].node");
        // bad load frame
        expect_error(
            "frame = \"follower\"",
            "frame = \"body\"",
            "frame = \"body\"",
            "loads[0].frame",
        );
        // non-positive time step
        expect_error("dt = 1e-3", "dt = 0.0", "dt = 0.0", "run.dt");
        // attach to an unknown joint
        expect_error(
            "attach = { joint = \"elbow\"",
            "attach = { joint = \"knee\"",
            "knee",
            "beams[1]",
        );
        // bad components
        expect_error(
            "components = \"planar\"",
            "components = \"flat\"",
            "components",
            "components",
        );
        // a support given a list of ends
        expect_error(
            "end = \"link1:start\"",
            "ends = [\"link1:start\"]",
            "[[supports]]",
            "supports[0].end",
        );
    }

    /// The closed-loop sections: each malformed value names its file, line and field.
    #[test]
    fn malformed_control_sections_name_file_line_and_field() {
        let base = format!(
            "{}{}",
            BASE.replace("force = [0.0, 0.0, 0.1]", "force = [0.0, 0.0, 1.0]\ncontrol = true"),
            r#"
[modes]
selection = "paper-2d"

[controller]
kind = "nmpc"
substeps = 16

[controller.weights]
ku = 0.1

[scenario]
axis = [0.0, 1.0, 0.0]
plant = "fe"
sampling = 0.2
duration = 1.0

[sweep]
omega0 = [0.5, 1.0]
controllers = ["nmpc"]
"#
        );
        let ok = load_str(Path::new("ok.toml"), &base).unwrap_or_else(|e| panic!("{e}"));
        let c = ok.control.expect("[scenario]");
        assert_eq!(c.sweep_omegas, [0.5, 1.0]);
        assert_eq!(c.scenario.inputs.len(), 1);
        let check = |from: &str, to: &str, at: &str, field: &str, allowed: &str| {
            assert!(base.contains(from), "base lacks {from}");
            let text = base.replacen(from, to, 1);
            let msg = match load_str(Path::new("bad.toml"), &text) {
                Ok(_) => panic!("`{to}` was accepted"),
                Err(e) => e.to_string(),
            };
            let line = line_of(&text, at);
            assert!(msg.starts_with(&format!("bad.toml:{line}:")), "line {line} in: {msg}");
            assert!(msg.contains(field), "field `{field}` in: {msg}");
            assert!(msg.contains(allowed), "`{allowed}` in: {msg}");
        };
        check(
            "kind = \"nmpc\"",
            "kind = \"pid\"",
            "kind = \"pid\"",
            "controller.kind",
            "nmpc, lmpc",
        );
        check(
            "plant = \"fe\"",
            "plant = \"beam\"",
            "plant = \"beam\"",
            "scenario.plant",
            "fe, rom",
        );
        check("ku = 0.1", "ku = -1.0", "ku = -1.0", "controller.weights.ku", "> 0");
        check("substeps = 16", "substeps = 0", "substeps = 0", "controller.substeps", "at least 1");
        check(
            "substeps = 16",
            "substeps = 16\nplan_joint_limit_deg = 200.0",
            "plan_joint_limit_deg = 200.0",
            "controller.plan_joint_limit_deg",
            "(0, 180]",
        );
        check(
            "substeps = 16",
            "substeps = 16\njoint_limit = false\nplan_joint_limit_deg = 25.0",
            "plan_joint_limit_deg = 25.0",
            "controller.plan_joint_limit_deg",
            "joint_limit = false",
        );
        check(
            "sampling = 0.2",
            "sampling = 0.33",
            "sampling = 0.33",
            "scenario.sampling",
            "multiple",
        );
        check(
            "duration = 1.0",
            "duration = 1.01",
            "duration = 1.01",
            "scenario.duration",
            "multiple",
        );
        check("sampling = 0.2", "sampling = 7.0", "sampling = 7.0", "scenario.sampling", "horizon");
        check(
            "axis = [0.0, 1.0, 0.0]\nplant",
            "axis = [0.0, 0.0, 0.0]\nplant",
            "axis = [0.0, 0.0, 0.0]",
            "scenario.axis",
            "non-zero",
        );
        check(
            "controllers = [\"nmpc\"]",
            "controllers = [\"lqr\"]",
            "controllers",
            "sweep.controllers",
            "nmpc, lmpc",
        );
        check("omega0 = [0.5, 1.0]", "omega0 = []", "omega0 = []", "sweep.omega0", "at least one");
        check(
            "selection = \"paper-2d\"",
            "selection = \"paper-2d\"\nlowest = 4",
            "selection = ",
            "modes.selection",
            "only one",
        );
        check(
            "selection = \"paper-2d\"",
            "selection = \"paper-9d\"",
            "selection",
            "modes.selection",
            "paper-2d, paper-3d",
        );
        check(
            "frame = \"follower\"",
            "frame = \"dead\"",
            "frame = \"dead\"",
            "loads[0].frame",
            "follower",
        );
        check(
            "force = [0.0, 0.0, 1.0]\ncontrol = true",
            "force = [0.0, 0.0, 1.0]",
            "[[loads]]",
            "loads[0].control",
            "control = true",
        );
        check("axis = [0.0, 1.0, 0.0]\nplant", "plant", "[scenario]", "axis", "missing");
        check(
            "[scenario]",
            "[scenario]\nroot = \"hip\"",
            "root = \"hip\"",
            "scenario.root",
            "supports: root",
        );
        check("[scenario]", "[scenario]\nspeed = 1.0", "speed", "speed", "unknown field");
    }

    /// Every shipped scene builds and takes a few steps (the full runs are in CI via the CLI).
    #[test]
    fn shipped_scenes_load_and_step() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().and_then(|e| e.to_str()) != Some("toml") {
                continue;
            }
            let mut s = load(&path).unwrap_or_else(|e| panic!("{e}"));
            if let Some(c) = &s.control {
                c.scenario.validate().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            }
            for _ in 0..3 {
                s.plant.step().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            }
            n += 1;
        }
        assert!(n >= 5, "found {n} scenes");
    }

    /// The shipped MPC scenes build the same closed loops as the mpc crate's presets
    /// (`Scenario::paper_2d(50)`, `paper_3d(50)`): structure size, inputs (up to their names),
    /// mode set, disturbance axis, root, timing and weights.
    #[test]
    fn shipped_mpc_scenes_match_the_mpc_presets() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
        for (file, preset) in [
            ("paper-2d-mpc.toml", mpc::Scenario::paper_2d(50).unwrap()),
            ("paper-3d-mpc.toml", mpc::Scenario::paper_3d(50).unwrap()),
            ("paper-3d-mpc-ku1.toml", {
                let mut p = mpc::Scenario::paper_3d(50).unwrap();
                p.mpc.ku = mpc::SPATIAL_INPUT_WEIGHT;
                p
            }),
        ] {
            let s = load(&dir.join(file)).unwrap_or_else(|e| panic!("{e}"));
            let c = s.control.expect("[scenario]");
            let sc = &c.scenario;
            assert_eq!(sc.structure.dim(), preset.structure.dim(), "{file}");
            assert_eq!(sc.structure.joints().len(), preset.structure.joints().len());
            let strip = |i: &mpc::ControlInput| match i {
                mpc::ControlInput::JointTorque { joint, axis, .. } => format!("T {joint} {axis:?}"),
                mpc::ControlInput::Follower { beam, node, load, .. } => {
                    format!("F {beam} {node} {load:?}")
                }
            };
            let a: Vec<String> = sc.inputs.iter().map(strip).collect();
            let b: Vec<String> = preset.inputs.iter().map(strip).collect();
            assert_eq!(a, b, "{file}");
            assert_eq!(format!("{:?}", sc.selection), format!("{:?}", preset.selection));
            assert_eq!(sc.omega_direction, preset.omega_direction);
            assert_eq!((sc.root.as_str(), sc.center), (preset.root.as_str(), preset.center));
            assert_eq!(
                (sc.duration, sc.output_interval, sc.snapshot_interval, sc.rom_plant_substeps),
                (preset.duration, preset.output_interval, preset.snapshot_interval, 16)
            );
            assert_eq!(sc.plant.dt, preset.plant.dt);
            assert_eq!(sc.mpc, preset.mpc);
            assert_eq!((c.plant, c.omega0), (mpc::PlantKind::Fe, 1.0));
            if file == "paper-3d-mpc-ku1.toml" {
                assert_eq!(c.controller, mpc::ControllerSettings::real_time_spatial());
            }
        }
    }

    /// The built-in default scene is the shipped paper 2D NMPC scene, with paper defaults and
    /// the real-time controller.
    #[test]
    fn default_scene_is_the_shipped_paper_2d_mpc() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(crate::DEFAULT_SCENE_PATH);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), crate::DEFAULT_SCENE);
        let s = load_str(Path::new(crate::DEFAULT_SCENE_PATH), crate::DEFAULT_SCENE).unwrap();
        let c = s.control.expect("the default scene has a [scenario]");
        assert_eq!(c.scenario.mpc, mpc::MpcSettings::default());
        // the shipped scene runs the real-time configuration (docs/mpc.md, "Real time")
        assert_eq!(c.controller, mpc::ControllerSettings::real_time(false));
        assert_eq!(c.scenario.inputs.len(), 3);
        assert_eq!(s.name, "paper-2d-mpc");
    }
}
