//! A reduced model run open loop from an FE state, observed in the FE plant's terms (node
//! rotations and positions, joint angles, energy): the paper's augmented model (29) or the
//! exact-joints model (theory.md §10), each advanced by its implicit midpoint rule. What
//! `flexmpc simulate --plant rom` runs, to put model and plant side by side.

use crate::error::{invalid, Result};
use crate::exact_dynamics::{default_link_elastic_modes, exact_joints_rom, ModelKind};
use crate::plant::{relative_angle, ExactPlant};
use intrinsic_beam::{Components, Kinematics};
use modal_rom::StructureModel;
use modal_rom::{BasisSettings, Input, ModalRom, ModeSelection, RomOptions};
use multibody_constraints::Structure;
use nalgebra::{Vector3, Vector4};

/// Newton tolerance and iteration limit of the midpoint steps.
const TOLERANCE: f64 = 1e-11;
const MAX_NEWTON: usize = 30;

enum State {
    Paper { rom: Box<ModalRom>, q: Vec<f64> },
    Exact(Box<ExactPlant>),
}

/// A reduced model of a structure as an open-loop plant.
pub struct ModalPlant {
    structure: Structure,
    model: StructureModel,
    state: State,
    root: usize,
    t: f64,
}

impl ModalPlant {
    /// The model `kind` of `structure` with the inputs `inputs` (modal input columns; see
    /// [`crate::ControlInput::modal`]), started from the FE state `x_fe` with node kinematics
    /// `kinematics` projected onto it (theory.md §7, §10). The paper's model uses the mode
    /// set `selection` with quaternion states; the exact-joints model the per-link basis with
    /// `elastic` modes (`None`: 4 planar, 16 spatial).
    pub fn new(
        kind: ModelKind,
        structure: &Structure,
        selection: &ModeSelection,
        elastic: Option<usize>,
        inputs: impl Fn(&Structure, &StructureModel) -> Result<Vec<Input>>,
        x_fe: &[f64],
        kinematics: &[Kinematics],
    ) -> Result<Self> {
        let model = StructureModel::new(structure)?;
        let inputs = inputs(structure, &model)?;
        let root = structure
            .joints()
            .iter()
            .position(|j| j.ground && !j.ends.is_empty())
            .ok_or_else(|| invalid("supports", 0, "the reduced models need a support"))?;
        let state = match kind {
            ModelKind::Paper => {
                let basis = model.modes(&BasisSettings::default())?.select(selection)?;
                let rom =
                    ModalRom::new(&basis, Some(&model.damping), &inputs, &RomOptions::default())?;
                let xi: Vec<[f64; 4]> = kinematics
                    .iter()
                    .flat_map(|k| k.xi.iter().map(|v| [v[0], v[1], v[2], v[3]]))
                    .collect();
                let q = rom.project_full(x_fe, Some(&xi))?;
                State::Paper { rom: Box::new(rom), q }
            }
            ModelKind::ExactJoints => {
                let spatial = matches!(structure.components(), Components::Spatial);
                let n = elastic.unwrap_or_else(|| default_link_elastic_modes(spatial));
                let rom = exact_joints_rom(structure, &model, n, &inputs)?;
                let x = rom.project_fe(x_fe, kinematics)?;
                State::Exact(Box::new(ExactPlant::new(rom, x, 1.0, 1)?))
            }
        };
        Ok(Self { structure: structure.clone(), model, state, root, t: 0.0 })
    }

    /// Time (s).
    pub fn time(&self) -> f64 {
        self.t
    }

    /// State dimension of the model.
    pub fn n_state(&self) -> usize {
        match &self.state {
            State::Paper { q, .. } => q.len(),
            State::Exact(p) => p.x.len(),
        }
    }

    /// One implicit-midpoint step of `dt` holding `u`; returns the Newton iterations.
    pub fn step(&mut self, u: &[f64], dt: f64) -> Result<usize> {
        let it = match &mut self.state {
            State::Paper { rom, q } => rom.midpoint_step(q, u, dt, TOLERANCE, MAX_NEWTON)?,
            State::Exact(p) => p.rom.midpoint_step(&mut p.x, u, dt, TOLERANCE, MAX_NEWTON)?,
        };
        self.t += dt;
        Ok(it)
    }

    /// Energy `½|q1|² + ½|q2|²` (the FE plant's kinetic + strain energy of the represented
    /// fields).
    pub fn energy(&self) -> f64 {
        match &self.state {
            State::Paper { rom, q } => rom.energy(q),
            State::Exact(p) => p.rom.energy(&p.x),
        }
    }

    /// Node rotations and positions of every beam: the paper model's quaternion field and
    /// positions rebuilt from its strains (eq. 10); the exact-joints model's configuration
    /// of `ExactPlant::configuration`.
    pub fn kinematics(&self) -> Result<Vec<Kinematics>> {
        match &self.state {
            State::Paper { rom, q } => {
                let fields = rom.reconstruct(q)?;
                let positions = rom.positions(q)?;
                let mut out = Vec::new();
                let mut node0 = 0;
                for (b, r) in positions.iter().enumerate() {
                    let xi = (0..r.len())
                        .map(|n| match &fields.xi {
                            Some(v) => Vector4::from_column_slice(&v[node0 + n]),
                            None => self.structure.reference()[b].xi[n],
                        })
                        .collect();
                    let r = r.iter().map(|p| Vector3::from_column_slice(p)).collect();
                    out.push(Kinematics { xi, r });
                    node0 += positions[b].len();
                }
                Ok(out)
            }
            State::Exact(p) => {
                Ok(p.configuration(&self.structure, &self.model.layout, self.root)?.1)
            }
        }
    }

    /// Joint angles in the FE plant's convention (`multibody_constraints::Plant::joint_angles`,
    /// structure order): planar structures the signed angle about the plane's normal (two-end
    /// joints including their reference angle, supports relative to their reference);
    /// spatial ones the relative rotation angle in `[0, π]`.
    pub fn joint_angles(&self, kinematics: &[Kinematics]) -> Vec<f64> {
        let planar = match self.structure.components() {
            Components::Planar => Some(1),
            Components::Spatial => None,
        };
        let reference = self.structure.reference();
        self.structure
            .joints()
            .iter()
            .map(|j| {
                let node = |k: &[Kinematics], i: usize| {
                    let (b, e) = j.ends[i];
                    k[b].xi[self.structure.end_node(b, e)]
                };
                match j.ends.len() {
                    1 => relative_angle(&node(reference, 0), &node(kinematics, 0), planar),
                    2 => relative_angle(&node(kinematics, 0), &node(kinematics, 1), planar),
                    _ => 0.0,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ControllerSettings, PlantKind, Scenario, Setup};

    /// The exact-joints model as closed-loop plant: a 1 s NMPC loop (2×6 elements, ω0 = 1)
    /// completes, slows the spin, and reports the model.
    #[test]
    fn exact_joints_rom_plant_runs_a_closed_loop() {
        let mut sc = Scenario::paper_2d(6).unwrap();
        sc.duration = 1.0;
        let setup = Setup::new(&sc).unwrap();
        let c = ControllerSettings {
            model: ModelKind::ExactJoints,
            plan_joint_limit_deg: None,
            fallback_to_lmpc: false,
            ..ControllerSettings::real_time(false)
        };
        let r = crate::run(&setup, 1.0, &c, PlantKind::Rom).unwrap();
        assert!(r.summary.error.is_none(), "{:?}", r.summary.error);
        assert_eq!(r.summary.model, "exact-joints");
        assert_eq!(r.summary.plant, "rom");
        assert!(r.summary.rigid_rate_ratio < 0.9, "{}", r.summary.rigid_rate_ratio);
        // energy of the plant recorded, decreasing from the spin's
        let (e0, e1) = (r.records[0].energy, r.records.last().unwrap().energy);
        assert!(e0 > 0.0 && e1 < e0, "{e0} → {e1}");
    }
}
