//! Scenarios: a structure, its control inputs, the controller's mode set, the disturbance and
//! the run's timing; the paper's 2D (§5.2) and 3D (§5.3) two-links. [`Setup`] holds what a
//! scenario's runs share (modes, reduced model, weights), built once per sweep.

use crate::error::{invalid, Result};
use crate::plant::ControlInput;
use crate::weights::{MpcSettings, Weights};
use intrinsic_beam::Section;
use modal_rom::{BasisSettings, ModalRom, ModeSelection, RomOptions, StructureModel};
use multibody_constraints::Structure;
use multibody_constraints::{samples, PlantSettings};
use nalgebra::Vector4;

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
    /// Lawson RK4 steps per output interval when the ROM is the plant [16].
    pub rom_plant_substeps: usize,
    /// Weights, horizon and timing of the MPC (paper defaults).
    pub mpc: MpcSettings,
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

    /// Checks timing (divisibility of `τs`, output, snapshot and plant steps) and the MPC
    /// settings.
    pub fn validate(&self) -> Result<()> {
        self.mpc.validate()?;
        self.plant.validate()?;
        self.rom_options.validate()?;
        if !self.rom_options.quaternions {
            return Err(invalid("rom_options.quaternions", false, "the cost (35) needs them"));
        }
        if !(self.duration.is_finite() && self.duration > 0.0) {
            return Err(invalid("duration", self.duration, "must be finite and > 0"));
        }
        if self.inputs.is_empty() {
            return Err(invalid("inputs", 0, "a controlled scenario needs at least one input"));
        }
        if self.rom_plant_substeps == 0 {
            return Err(invalid("rom_plant_substeps", 0, "must be at least 1"));
        }
        ratio("output_interval per sampling", self.mpc.sampling, self.output_interval)?;
        let dt_plan = self.mpc.horizon / self.mpc.intervals as f64;
        if self.mpc.control_grid == crate::weights::ControlGrid::Absolute
            || self.mpc.sampling > dt_plan + 1e-12
        {
            // the plan's switching times must fall on output-interval boundaries
            ratio("output_interval per control interval τp/Nc", dt_plan, self.output_interval)?;
        }
        ratio("output_interval per duration", self.duration, self.output_interval)?;
        ratio("plant.dt per output_interval", self.output_interval, self.plant.dt)?;
        ratio(
            "output_interval per snapshot_interval",
            self.snapshot_interval,
            self.output_interval,
        )?;
        if self.omega_direction.iter().any(|v| !v.is_finite()) {
            return Err(invalid(
                "omega_direction",
                format!("{:?}", self.omega_direction),
                "must be finite",
            ));
        }
        if self.structure.joint_index(&self.root).is_none() {
            return Err(invalid("root", &self.root, "no such support"));
        }
        Ok(())
    }
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
        let weights = Weights::new(&rom, &scenario.mpc, &pairs)?;
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
