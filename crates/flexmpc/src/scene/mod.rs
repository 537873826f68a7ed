//! Scene files (TOML): sections, beams and meshes, joints, supports, loads and inputs,
//! initial conditions, run settings, and the closed loop's `[modes]`, `[controller]`,
//! `[scenario]` and `[sweep]` — parsed with serde into a [`Scene`]: the structure, the inputs
//! and, for a closed loop, the `mpc` crate's own settings, each checked by that crate's
//! `validate()`. The FE plant of `simulate` is built by [`Scene::plant`]; [`check`] builds
//! what every command builds before it runs. Every error names the file, the line and the
//! field (library errors through their typed field and a table of scene keys).

mod control;
mod error;
mod inputs;
mod names;
mod reference;
mod spec;
mod structure;
#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use intrinsic_beam::{Amplitude, PointLoad};
use multibody_constraints::Structure;
use multibody_constraints::{MultibodyError, Plant, PlantSettings};
use nalgebra::Vector3;

pub use control::{controller_kind, model_kind, plant_kind};
pub use error::SceneError;
use error::{field_at, field_from_message, table_at, Ctx};
pub use names::*;
pub use spec::*;
pub use structure::MAX_ELEMENTS_PER_BEAM;

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

/// A scene ready to run: the structure and everything built on it. The FE plant of
/// `simulate` is built by [`Scene::plant`]; closed loops build theirs in `mpc`.
pub struct Scene {
    /// Source file.
    pub file: PathBuf,
    /// The structure (beams, joints, supports) in its reference configuration.
    pub structure: Structure,
    /// Settings of the FE plant (`[run] dt`, `newton_tolerance`).
    pub plant_settings: PlantSettings,
    /// Number of steps of `simulate`.
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
    /// The parsed file and its text (errors of [`Scene::plant`] name their line), and the
    /// point loads per beam.
    source: Source,
}

struct Source {
    text: String,
    spec: SceneSpec,
    loads: Vec<(usize, PointLoad)>,
}

impl Scene {
    /// The FE plant of `simulate` in its initial state: gravity, the point loads, the torques
    /// at `t = 0` (control inputs at 0) and `[[initial.rigid]]`. Errors name the torque, the
    /// initial rotation or the gravity that the plant refused.
    pub fn plant(&self) -> Result<Plant, SceneError> {
        let ctx = Ctx { file: &self.file, text: &self.source.text };
        let spec = &self.source.spec;
        let mut plant = Plant::new(self.structure.clone(), self.plant_settings)
            .or_else(|e| ctx.err(Some(spec.run.span()), "run", e.to_string()))?;
        if let Some(g) = spec.gravity {
            plant
                .set_gravity(Vector3::from(g))
                .or_else(|e| ctx.err(None, "gravity", e.to_string()))?;
        }
        inputs::apply(&ctx, spec, &mut plant, &self.source.loads, &self.inputs)?;
        inputs::initial_state(&ctx, spec, &mut plant)?;
        Ok(plant)
    }
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
        if let Some(err) = e.span().and_then(|s| flattened(&ctx, s, &message)) {
            return err;
        }
        // "invalid type/value/length: … `-4` …" and "unknown variant `pid`, expected …" quote
        // the value, not the field: take the key at the span for those.
        let quotes_field =
            !(message.starts_with("invalid") || message.starts_with("unknown variant"));
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

/// An error in a table that flattens a library type (`[scenario]`: [`mpc::Timing`]): serde
/// reports it at the table's header and, for a wrong value, without the key. The key is the
/// one named by an unknown-field message, or the table's key whose value the library type
/// alone refuses; the line is that key's line.
fn flattened(ctx: &Ctx<'_>, span: std::ops::Range<usize>, message: &str) -> Option<SceneError> {
    if !ctx.text.get(span.start..)?.starts_with('[') {
        return None;
    }
    let table = table_at(ctx.text, span.start)?;
    let key = if message.starts_with("unknown field") {
        field_from_message(message)?
    } else if table == "scenario" {
        let doc: toml::Table = toml::from_str(ctx.text).ok()?;
        let entries = doc.get("scenario")?.as_table()?;
        entries.iter().find_map(|(k, v)| {
            let one = toml::Table::from_iter([(k.clone(), v.clone())]);
            match toml::Value::Table(one).try_into::<mpc::Timing>() {
                Err(e) if !e.message().starts_with("unknown field") => Some(k.clone()),
                _ => None,
            }
        })?
    } else {
        return None;
    };
    ctx.err::<()>(Some(span), format!("{table}.{key}"), message).err()
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

/// A scene with everything its commands build before they run: what `flexmpc check` checks.
pub struct Checked {
    /// The scene.
    pub scene: Scene,
    /// The FE plant of `simulate`, in its initial state.
    pub plant: Plant,
    /// The closed loop's setup (modes, reduced model, weights) when the scene has a
    /// `[scenario]`.
    pub setup: Option<mpc::Setup>,
}

/// Loads a scene and builds what `simulate`, `modes`, `mpc`, `sweep` and `ocp` build before
/// they run, through the library's own checks: the scene ([`load`]), the plant of
/// `simulate` ([`Scene::plant`]) and, for a closed-loop scene, [`mpc::Setup::new`] (the
/// modes fill the mode set; the control inputs act on the model).
pub fn check(file: &Path) -> Result<Checked, SceneError> {
    let (spec, text) = parse(file)?;
    checked(build(file, &text, spec)?)
}

/// [`check`] of scene text (`file` names it in errors).
pub fn check_str(file: &Path, text: &str) -> Result<Checked, SceneError> {
    checked(load_str(file, text)?)
}

fn checked(scene: Scene) -> Result<Checked, SceneError> {
    let plant = scene.plant()?;
    let setup = match &scene.control {
        None => None,
        Some(c) => {
            let ctx = Ctx { file: &scene.file, text: &scene.source.text };
            Some(control::setup_of(&ctx, &scene.source.spec, c)?)
        }
    };
    Ok(Checked { scene, plant, setup })
}

/// Most steps a `simulate` run may take (`[run] duration / dt`), that of a closed loop
/// ([`mpc::MAX_PLANT_STEPS`]).
pub const MAX_STEPS: usize = mpc::MAX_PLANT_STEPS;

fn build(file: &Path, text: &str, spec: SceneSpec) -> Result<Scene, SceneError> {
    let ctx = Ctx { file, text };
    let (structure, beam_names) = structure::structure_of(&ctx, &spec)?;
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
    let plant_settings = PlantSettings {
        dt: run.dt,
        newton_tolerance: run.newton_tolerance.unwrap_or(1e-12),
        ..Default::default()
    };
    plant_settings.validate().or_else(|e| match e {
        MultibodyError::BadSetting { field, value, reason } => {
            ctx.err(run_span.clone(), format!("run.{field}"), format!("{reason}, got {value}"))
        }
        e => ctx.err(run_span.clone(), "run", e.to_string()),
    })?;
    let inputs = inputs::inputs_of(&ctx, &spec, &structure, &beam_names)?;
    let steps = run.duration / run.dt;
    if steps > MAX_STEPS as f64 {
        return ctx.err(
            run_span,
            "run.duration",
            format!(
                "{} s is {steps:.3e} steps of dt = {} s; at most {MAX_STEPS}",
                run.duration, run.dt
            ),
        );
    }
    if run.duration > 0.0 && !((steps - steps.round()).abs() <= 1e-9 * steps && steps >= 0.5) {
        return ctx.err(
            run_span,
            "run.duration",
            format!(
                "{} s must be a whole multiple (≥ 1) of dt = {} s (the run steps by dt)",
                run.duration, run.dt
            ),
        );
    }
    let steps = steps.round() as usize;
    let output_every = run.output_every.unwrap_or(10);
    if output_every == 0 {
        return ctx.err(run_span, "run.output_every", "must be at least 1");
    }
    let name =
        file.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "scene".into());
    let (mode_count, mode_angles) = control::modes_of(&ctx, &spec)?;
    let control =
        control::control_of(&ctx, &spec, &structure, plant_settings, inputs.controls, &name)?;
    Ok(Scene {
        file: file.to_path_buf(),
        structure,
        plant_settings,
        steps,
        output_every,
        inputs: inputs.inputs,
        plot: spec.output.plot.clone(),
        title: spec.output.title.clone().unwrap_or_default(),
        description: spec.description.clone().unwrap_or_default(),
        name,
        mode_count,
        mode_angles,
        control,
        source: Source { text: text.to_string(), spec, loads: inputs.loads },
    })
}
