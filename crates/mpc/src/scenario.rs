//! Scenarios: a structure, its control inputs, the controller's mode set, the disturbance and
//! the run's timing; the paper's 2D (§5.2) and 3D (§5.3) two-links. [`Setup`] holds what a
//! scenario's runs share (modes, reduced model, weights), built once per sweep.

use crate::error::{invalid, MpcError, Result};
use crate::plant::ControlInput;
use crate::reference::JointCommand;
use crate::weights::{MpcSettings, Weights};
use intrinsic_beam::Section;
use modal_rom::{BasisSettings, ModalRom, ModeSelection, RomOptions, StructureModel};
use multibody_constraints::Structure;
use multibody_constraints::{samples, PlantSettings};
use nalgebra::{Vector3, Vector4};

/// A closed-loop stabilisation scenario (paper §5.2–5.3).
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Name (e.g. `paper-2d`).
    pub name: String,
    /// The FE structure (plant, and source of the modes).
    pub structure: Structure,
    /// Control inputs, in the order of `u`.
    pub inputs: Vec<ControlInput>,
    /// Modes of the controller's model (paper: 2 rigid + 4 axial + 4 bending in 2D).
    pub selection: ModeSelection,
    /// Options of the reduced model (quaternion states are required).
    pub rom_options: RomOptions,
    /// Direction of the initial rigid rotation rate (global); the run's rate is `ω0 ·` this
    /// (2D: e2; 3D: e2 + e3, magnitude `√2 ω0`).
    pub omega_direction: [f64; 3],
    /// Centre of the initial rigid rotation (the root).
    pub center: [f64; 3],
    /// Support whose angle measures the root link's orientation (`root`).
    pub root: String,
    /// Duration of a closed loop (s) [7.5].
    pub duration: f64,
    /// Interval of the recorded time series (s), a divisor of `τs` [0.05].
    pub output_interval: f64,
    /// Interval of the snapshots of the deformed structure (s), a multiple of
    /// `output_interval` [0.25].
    pub snapshot_interval: f64,
    /// FE plant settings (`dt` must divide `output_interval`) [dt = 1e-3].
    pub plant: PlantSettings,
    /// Lawson RK4 steps per output interval when the ROM is the plant \[16\].
    pub rom_plant_substeps: usize,
    /// Weights, horizon and timing of the MPC (paper defaults).
    pub mpc: MpcSettings,
    /// Commanded joint rotations (reconfiguration; [`crate::reference`]) \[none: every joint
    /// held at its reference angle\]. Only the exact-joints controller model can follow them.
    pub references: Vec<JointCommand>,
}

impl Scenario {
    /// The paper's 2D two-link (§5.2) with `n_elements` per link (paper scene: 50): root hinge
    /// torque, axial and transverse follower forces at the tip; 2 rigid + 4 axial + 4 bending
    /// modes at 0°; disturbance about e2.
    pub fn paper_2d(n_elements: usize) -> Result<Self> {
        let structure = samples::paper_2d(Section::paper_2d(), n_elements, 0.0)?;
        let tip = n_elements;
        Ok(Self {
            name: "paper-2d".into(),
            structure,
            inputs: vec![
                ControlInput::JointTorque {
                    name: "root torque".into(),
                    joint: "root".into(),
                    axis: None,
                },
                ControlInput::Follower {
                    name: "tip force e1".into(),
                    beam: 1,
                    node: tip,
                    load: [1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                },
                ControlInput::Follower {
                    name: "tip force e3".into(),
                    beam: 1,
                    node: tip,
                    load: [0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
                },
            ],
            selection: modal_rom::samples::paper_2d_selection(),
            rom_options: RomOptions::default(),
            omega_direction: [0.0, 1.0, 0.0],
            center: [0.0; 3],
            root: "root".into(),
            duration: 7.5,
            output_interval: 0.05,
            snapshot_interval: 0.25,
            plant: PlantSettings::default(),
            rom_plant_substeps: 16,
            mpc: MpcSettings::default(),
            references: Vec::new(),
        })
    }

    /// The paper's 3D two-link (§5.3): universal joints, two follower bending moments at the
    /// root and three follower forces at the tip; 4 rigid + 4 axial + 4 torsion + 4 + 4
    /// bending modes at 0°; disturbance `ω0 (e2 + e3)`.
    pub fn paper_3d(n_elements: usize) -> Result<Self> {
        let structure = samples::paper_3d(Section::paper_3d(), n_elements, 0.0)?;
        let tip = n_elements;
        let mut inputs = Vec::new();
        for (a, name) in [(4, "root moment e2"), (5, "root moment e3")] {
            let mut load = [0.0; 6];
            load[a] = 1.0;
            inputs.push(ControlInput::Follower { name: name.into(), beam: 0, node: 0, load });
        }
        for (a, name) in [(0, "tip force e1"), (1, "tip force e2"), (2, "tip force e3")] {
            let mut load = [0.0; 6];
            load[a] = 1.0;
            inputs.push(ControlInput::Follower { name: name.into(), beam: 1, node: tip, load });
        }
        let mut s = Self::paper_2d(n_elements)?;
        s.name = "paper-3d".into();
        s.structure = structure;
        s.inputs = inputs;
        s.selection = modal_rom::samples::paper_3d_selection();
        s.omega_direction = [0.0, 1.0, 1.0];
        Ok(s)
    }

    /// Checks every field: the MPC settings (errors name `mpc.<field>`), the plant settings
    /// (`plant.<field>`), the reduced-model options (`rom_options.<field>`); times finite and
    /// positive, each a whole multiple of the one it is sampled on (`τs`, `τp/Nc`, the
    /// duration and the snapshot interval of `output_interval`, which is one of `plant.dt`),
    /// at most [`MAX_PLANT_STEPS`] plant steps; the disturbance axis finite and non-zero, the
    /// centre finite, `root` a support of the structure, at least one input.
    pub fn validate(&self) -> Result<()> {
        self.mpc.validate().map_err(|e| e.within("mpc"))?;
        self.plant.validate().map_err(|e| MpcError::from(e).within("plant"))?;
        self.rom_options.validate().map_err(|e| MpcError::from(e).within("rom_options"))?;
        if !self.rom_options.quaternions {
            return Err(invalid("rom_options.quaternions", false, "the cost (35) needs them"));
        }
        for (field, v) in [
            ("duration", self.duration),
            ("output_interval", self.output_interval),
            ("snapshot_interval", self.snapshot_interval),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(field, v, "must be finite and > 0"));
            }
        }
        if self.inputs.is_empty() {
            return Err(invalid("inputs", 0, "a controlled scenario needs at least one input"));
        }
        if self.rom_plant_substeps == 0 {
            return Err(invalid("rom_plant_substeps", 0, "must be at least 1"));
        }
        let out = ("output_interval", self.output_interval);
        multiple("mpc.sampling", self.mpc.timing.sampling, out)?;
        let dt_plan = self.mpc.timing.horizon / self.mpc.timing.intervals as f64;
        if self.mpc.control_grid == crate::weights::ControlGrid::Absolute
            || self.mpc.timing.sampling > dt_plan + 1e-12
        {
            // the plan's switching times must fall on output-interval boundaries
            multiple("mpc.intervals", dt_plan, out).map_err(|e| {
                let e = e.with_reason(|r| format!("gives τp/Nc = {dt_plan} s, which {r}"));
                e.with_value(self.mpc.timing.intervals)
            })?;
        }
        multiple("duration", self.duration, out)?;
        multiple("output_interval", self.output_interval, ("plant.dt", self.plant.dt))?;
        multiple("snapshot_interval", self.snapshot_interval, out)?;
        let steps = self.duration / self.plant.dt;
        if steps > MAX_PLANT_STEPS as f64 {
            return Err(invalid(
                "duration",
                self.duration,
                format!(
                    "must be at most {MAX_PLANT_STEPS} plant steps of plant.dt = {} s \
                     ({steps:.3e})",
                    self.plant.dt
                ),
            ));
        }
        self.validate_references()?;
        if self.omega_direction.iter().any(|v| !v.is_finite())
            || self.omega_direction.iter().all(|v| *v == 0.0)
        {
            return Err(invalid(
                "omega_direction",
                format!("{:?}", self.omega_direction),
                "must be finite and non-zero",
            ));
        }
        if self.center.iter().any(|v| !v.is_finite()) {
            return Err(invalid("center", format!("{:?}", self.center), "must be finite"));
        }
        let supports: Vec<&str> =
            self.structure.joints().iter().filter(|j| j.ground).map(|j| j.name.as_str()).collect();
        if !supports.contains(&self.root.as_str()) {
            return Err(invalid(
                "root",
                &self.root,
                if supports.is_empty() {
                    "the structure has no support".to_string()
                } else {
                    format!("must name a support (supports: {})", supports.join(", "))
                },
            ));
        }
        Ok(())
    }
}

impl Scenario {
    /// The FE plant's initial state of a run with disturbance `omega0`: the undeformed
    /// structure in rigid rotation at `omega0 · omega_direction` about `center`.
    pub fn disturbed_state(&self, omega0: f64) -> Vec<f64> {
        let omega = Vector3::from_column_slice(&self.omega_direction) * omega0;
        self.structure.rigid_rotation_state(omega, Vector3::from_column_slice(&self.center))
    }

    /// Each command valid (errors name `references[i].<field>`), on a joint or support of the
    /// structure, at most one per joint.
    fn validate_references(&self) -> Result<()> {
        for (i, c) in self.references.iter().enumerate() {
            let at = format!("references[{i}]");
            c.validate().map_err(|e| e.within(&at))?;
            let Some(j) = self.structure.joint_index(&c.joint) else {
                let names: Vec<&str> =
                    self.structure.joints().iter().map(|j| j.name.as_str()).collect();
                return Err(invalid(
                    format!("{at}.joint"),
                    &c.joint,
                    format!("must name a joint or support ({})", names.join(", ")),
                ));
            };
            if self.structure.joints()[j].ends.is_empty() {
                return Err(invalid(format!("{at}.joint"), &c.joint, "has no end"));
            }
            if self.references[..i].iter().any(|d| d.joint == c.joint) {
                return Err(invalid(format!("{at}.joint"), &c.joint, "has a command already"));
            }
        }
        Ok(())
    }
}

/// Most plant steps (`duration / plant.dt`) a closed loop may take: beyond it a run would take
/// days, and no scenario of the paper needs more than 10⁴.
pub const MAX_PLANT_STEPS: usize = 10_000_000;

/// `a` (the value of `field`) as a whole multiple (≥ 1, to 1e-9 relative) of `b = (name, value)`.
fn multiple(field: &str, a: f64, (name, b): (&str, f64)) -> Result<()> {
    let r = a / b;
    let n = r.round();
    if !(n >= 1.0 && (r - n).abs() <= 1e-9 * n) {
        return Err(invalid(field, a, format!("must be a whole multiple (≥ 1) of {name} = {b} s")));
    }
    Ok(())
}

/// `a / b` as a whole number ≥ 1 (to 1e-9 relative).
pub(crate) fn ratio(what: &str, a: f64, b: f64) -> Result<usize> {
    let r = a / b;
    let n = r.round();
    if !(n >= 1.0 && (r - n).abs() <= 1e-9 * n) {
        return Err(invalid(what, format!("{a} / {b}"), "must be a whole number ≥ 1"));
    }
    Ok(n as usize)
}

/// What every run of a scenario shares: the modes, the controller's reduced model, the
/// assembled weights, and the node indices used by the metrics.
#[derive(Clone, Debug)]
pub struct Setup {
    /// The scenario.
    pub scenario: Scenario,
    /// Operators and layout of the structure.
    pub model: StructureModel,
    /// The controller's augmented reduced model.
    pub rom: ModalRom,
    /// The cost (35)–(36).
    pub weights: Weights,
    /// Per joint (structure order): global node indices of its ends (one for a support).
    pub joint_nodes: Vec<Vec<usize>>,
    /// Joint names (structure order).
    pub joint_names: Vec<String>,
    /// Index of the root support among the joints.
    pub root_joint: usize,
    /// `Some(axis)` (local rotation component) for planar structures: signed joint angles.
    pub planar_axis: Option<usize>,
    /// Reference quaternion per global node.
    pub reference_xi: Vec<Vector4<f64>>,
}

impl Setup {
    /// Computes the modes, selects the scenario's set, builds the reduced model with the
    /// scenario's inputs and assembles the weights.
    pub fn new(scenario: &Scenario) -> Result<Self> {
        scenario.validate()?;
        let structure = &scenario.structure;
        let model = StructureModel::new(structure)?;
        let basis = model.modes(&BasisSettings::default())?.select(&scenario.selection)?;
        let inputs = scenario
            .inputs
            .iter()
            .map(|i| i.modal(structure, &model))
            .collect::<Result<Vec<_>>>()?;
        let rom = ModalRom::new(&basis, Some(&model.damping), &inputs, &scenario.rom_options)?;
        let mut first = Vec::new();
        let mut acc = 0;
        for b in structure.beams() {
            first.push(acc);
            acc += b.beam.n_nodes();
        }
        let joint_nodes: Vec<Vec<usize>> = structure
            .joints()
            .iter()
            .map(|j| j.ends.iter().map(|&(b, e)| first[b] + structure.end_node(b, e)).collect())
            .collect();
        let pairs: Vec<(usize, usize)> = structure
            .joints()
            .iter()
            .zip(&joint_nodes)
            .filter(|(j, n)| !j.ground && n.len() == 2)
            .map(|(_, n)| (n[0], n[1]))
            .collect();
        let weights = Weights::new(&rom, &scenario.mpc.cost, &pairs)?;
        let root_joint = structure
            .joint_index(&scenario.root)
            .ok_or_else(|| invalid("root", &scenario.root, "no such support"))?;
        let planar_axis = match structure.components() {
            intrinsic_beam::Components::Planar => Some(1),
            intrinsic_beam::Components::Spatial => None,
        };
        let reference_xi =
            structure.reference().iter().flat_map(|k| k.xi.iter().copied()).collect();
        Ok(Self {
            scenario: scenario.clone(),
            model,
            rom,
            weights,
            joint_nodes,
            joint_names: structure.joints().iter().map(|j| j.name.clone()).collect(),
            root_joint,
            planar_axis,
            reference_xi,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type Edit = fn(&mut Scenario);

    /// Each rule of [`Scenario::validate`] fails on its own field, so that a front end can
    /// map the error to the key of its input.
    #[test]
    fn validate_names_the_field_of_each_rule() {
        let base = Scenario::paper_2d(4).unwrap();
        base.validate().unwrap();
        let cases: [(&str, Edit); 16] = [
            ("mpc.horizon", |s| s.mpc.timing.horizon = -1.0),
            ("mpc.sampling", |s| s.mpc.timing.sampling = 0.33),
            ("mpc.sampling", |s| s.mpc.timing.sampling = 7.0),
            ("mpc.intervals", |s| s.mpc.timing.intervals = 7),
            ("mpc.ku", |s| s.mpc.cost.ku = 0.0),
            ("duration", |s| s.duration = 1.01),
            ("duration", |s| s.duration = 1e5),
            ("output_interval", |s| s.output_interval = 0.0),
            ("output_interval", |s| s.plant.dt = 0.03),
            ("snapshot_interval", |s| s.snapshot_interval = 0.26),
            ("plant.dt", |s| s.plant.dt = -1.0),
            ("omega_direction", |s| s.omega_direction = [0.0; 3]),
            ("center", |s| s.center = [f64::NAN, 0.0, 0.0]),
            ("root", |s| {
                s.root = s.structure.joints().iter().find(|j| !j.ground).unwrap().name.clone()
            }),
            ("inputs", |s| s.inputs.clear()),
            ("rom_plant_substeps", |s| s.rom_plant_substeps = 0),
        ];
        for (field, edit) in cases {
            let mut s = base.clone();
            edit(&mut s);
            match s.validate() {
                Err(MpcError::Invalid { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {other:?}"),
            }
        }
    }
}
