//! The plants a controller acts on: the constrained FE model (multibody-constraints) or the
//! modal model itself, with the inputs defined once for both.

use crate::dynamics::RomDynamics;
use crate::error::{invalid, MpcError, Result};
use intrinsic_beam::rotation::{quat_conj, quat_mul};
use intrinsic_beam::Kinematics;
use intrinsic_beam::{Amplitude, LoadFrame, PointLoad};
use modal_rom::{ExactJointsRom, FullIndex, Input, ModalRom, StructureModel};
use multibody_constraints::Structure;
use multibody_constraints::{Plant, PlantSettings};
use nalgebra::{Vector4, Vector6};
use ocp_transcription::{Integrator, IntegratorKind, IntegratorSettings};
use serde::{Deserialize, Serialize};

/// One control input, defined once for the controller's model and the plant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ControlInput {
    /// A torque about a free rotation axis of a joint or support (`axis`: index among the
    /// joint's axes, `None` for its only free rotation axis); the plant's sign convention
    /// (`+τ` on the second end, `−τ` on the first; a support's on its end).
    JointTorque {
        /// Input name.
        name: String,
        /// Joint or support name.
        joint: String,
        /// Free rotation axis.
        axis: Option<usize>,
    },
    /// A follower point load `u · load` at node `node` of beam `beam` (`[f, m]`, local frame).
    Follower {
        /// Input name.
        name: String,
        /// Beam index.
        beam: usize,
        /// Node index.
        node: usize,
        /// Unit load `[f1, f2, f3, m1, m2, m3]` (local).
        load: [f64; 6],
    },
}

impl ControlInput {
    /// The input's name.
    pub fn name(&self) -> &str {
        match self {
            ControlInput::JointTorque { name, .. } | ControlInput::Follower { name, .. } => name,
        }
    }

    /// The modal input `B_u` column definition of this input.
    pub fn modal(&self, structure: &Structure, model: &StructureModel) -> Result<Input> {
        Ok(match self {
            ControlInput::JointTorque { name, joint, axis } => {
                model.joint_torque(structure, name, joint, *axis)?
            }
            ControlInput::Follower { name, beam, node, load } => {
                Input::point(&model.layout, name, *beam, *node, *load)?
            }
        })
    }
}

/// Which plant the controller acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PlantKind {
    /// The constrained FE model (joints as hard constraints), the paper's plant.
    Fe,
    /// The controller's reduced model itself (fast studies; no model mismatch): the paper's
    /// augmented modal model (Lawson RK4) or the exact-joints model (implicit midpoint).
    Rom,
}

impl PlantKind {
    /// `"fe"` or `"rom"`.
    pub fn name(self) -> &'static str {
        match self {
            PlantKind::Fe => "fe",
            PlantKind::Rom => "rom",
        }
    }
}

/// Joint angle of the relative rotation between two node quaternions, signed about `axis`
/// when given (planar), else `2 acos|ξ_rel,0|` in `[0, π]`.
pub(crate) fn relative_angle(
    a: &Vector4<f64>,
    b: &Vector4<f64>,
    planar_axis: Option<usize>,
) -> f64 {
    let rel = quat_mul(&quat_conj(a), b);
    let rel = rel / rel.norm();
    match planar_axis {
        Some(ax) => {
            let s = if rel[0] < 0.0 { -1.0 } else { 1.0 };
            2.0 * (s * rel[1 + ax]).atan2(s * rel[0])
        }
        None => 2.0 * rel[0].abs().min(1.0).acos(),
    }
}

/// A plant in a closed loop.
pub(crate) enum SimPlant {
    Fe { plant: Box<Plant>, handles: Vec<Handle>, steps: usize },
    Rom { model: RomDynamics, integrator: Box<Integrator>, q: Vec<f64>, t: f64, buf: Vec<f64> },
    Exact(Box<ExactPlant>),
}

/// How an input reaches the FE plant.
pub(crate) enum Handle {
    Torque { joint: String, axis: Option<usize> },
    Load { beam: usize, index: usize, load: Vector6<f64> },
}

impl SimPlant {
    /// The FE plant with the inputs attached and the initial state `x0` (full FE vector);
    /// [`SimPlant::advance`] takes `steps` plant steps.
    pub fn fe(
        structure: &Structure,
        settings: PlantSettings,
        steps: usize,
        inputs: &[ControlInput],
        x0: &[f64],
    ) -> Result<Self> {
        let mut plant = Plant::new(structure.clone(), settings)?;
        plant.set_state(x0)?;
        let mut handles = Vec::new();
        for i in inputs {
            match i {
                ControlInput::JointTorque { joint, axis, .. } => {
                    plant.set_joint_torque(joint, *axis, 0.0)?;
                    handles.push(Handle::Torque { joint: joint.clone(), axis: *axis });
                }
                ControlInput::Follower { name, beam, node, load } => {
                    if *beam >= structure.beams().len() {
                        return Err(invalid(format!("input `{name}` beam"), beam, "no such beam"));
                    }
                    let loads = plant.loads_mut(*beam);
                    loads.point.push(PointLoad {
                        node: *node,
                        frame: LoadFrame::Follower,
                        value: Vector6::zeros(),
                        amplitude: Amplitude::Constant,
                    });
                    handles.push(Handle::Load {
                        beam: *beam,
                        index: loads.point.len() - 1,
                        load: Vector6::from_column_slice(load),
                    });
                }
            }
        }
        Ok(SimPlant::Fe { plant: Box::new(plant), handles, steps })
    }

    /// The modal model as plant, from the modal state `q0`, integrated by Lawson RK4 with
    /// `substeps` steps per [`SimPlant::advance`] of length `interval`.
    pub fn rom(rom: &ModalRom, q0: Vec<f64>, interval: f64, substeps: usize) -> Result<Self> {
        let model = RomDynamics::new(rom)?;
        let integrator = Integrator::new(
            &model,
            &IntegratorSettings::new(IntegratorKind::LawsonRk4, substeps),
            interval,
        )?;
        let n = q0.len();
        Ok(SimPlant::Rom {
            model,
            integrator: Box::new(integrator),
            q: q0,
            t: 0.0,
            buf: vec![0.0; n],
        })
    }

    /// Holds `u` for one output interval (the FE plant: `steps` steps of its `dt`; the ROM:
    /// one integrator pass).
    pub fn advance(&mut self, u: &[f64]) -> Result<()> {
        match self {
            SimPlant::Fe { plant, handles, steps } => {
                for (h, &v) in handles.iter().zip(u) {
                    match h {
                        Handle::Torque { joint, axis } => {
                            plant.set_joint_torque(joint, *axis, v)?
                        }
                        Handle::Load { beam, index, load } => {
                            plant.loads_mut(*beam).point[*index].value = load * v;
                        }
                    }
                }
                for _ in 0..*steps {
                    plant.step()?;
                }
                Ok(())
            }
            SimPlant::Rom { model, integrator, q, t, buf } => {
                integrator.integrate(&*model, q, u, buf)?;
                if buf.iter().any(|v| !v.is_finite()) {
                    return Err(MpcError::PlantDiverged { t: *t });
                }
                q.copy_from_slice(buf);
                *t += integrator.interval();
                Ok(())
            }
            SimPlant::Exact(p) => p.advance(u),
        }
    }
}

/// The exact-joints reduced model (theory.md §10) as a plant: advanced by its implicit
/// midpoint rule (energy-preserving, theory.md §10.4) with `steps` steps of `dt` per
/// [`SimPlant::advance`], and observed through the FE configuration it represents
/// ([`ExactPlant::configuration`]).
pub(crate) struct ExactPlant {
    pub rom: ExactJointsRom,
    /// State `[p, p2, ξ_root, ξ_j…]`.
    pub x: Vec<f64>,
    pub t: f64,
    pub dt: f64,
    pub steps: usize,
}

fn beam_error(e: intrinsic_beam::BeamError) -> MpcError {
    invalid("exact-joints plant configuration", e, "the strains must rebuild the beam")
}

/// Newton tolerance and iteration limit of the exact-joints plant's midpoint steps.
const EXACT_PLANT_TOLERANCE: f64 = 1e-11;
const EXACT_PLANT_MAX_NEWTON: usize = 30;

impl ExactPlant {
    /// The plant from the state `x0`, advancing by `interval` per [`SimPlant::advance`] in
    /// `substeps` midpoint steps.
    pub fn new(rom: ExactJointsRom, x0: Vec<f64>, interval: f64, substeps: usize) -> Result<Self> {
        if x0.len() != rom.n_state() {
            return Err(invalid(
                "exact-joints plant state",
                x0.len(),
                format!("must have {} entries", rom.n_state()),
            ));
        }
        if substeps == 0 || !(interval.is_finite() && interval > 0.0) {
            return Err(invalid(
                "rom plant steps",
                substeps,
                "needs ≥ 1 step of a positive interval",
            ));
        }
        if rom.n_p2() != rom.basis().n2() {
            return Err(invalid(
                "exact-joints plant",
                rom.n_p2(),
                format!("needs the full force fields (p2 = q2, {} coordinates)", rom.basis().n2()),
            ));
        }
        Ok(Self { rom, x: x0, t: 0.0, dt: interval / substeps as f64, steps: substeps })
    }

    /// Holds `u` for `steps` midpoint steps.
    pub fn advance(&mut self, u: &[f64]) -> Result<()> {
        for _ in 0..self.steps {
            self.rom
                .midpoint_step(
                    &mut self.x,
                    u,
                    self.dt,
                    EXACT_PLANT_TOLERANCE,
                    EXACT_PLANT_MAX_NEWTON,
                )
                .map_err(|_| MpcError::PlantDiverged { t: self.t })?;
            self.t += self.dt;
        }
        Ok(())
    }

    /// The FE configuration the model's state represents: the full FE vector
    /// (`x1 = Φ1 Z(ξ) p`, `x2 = Φ2 p2`, theory.md §10.2–10.4) and each beam's nodes rebuilt in
    /// space from its strains (eqs. 7, 10), starting from the root support's node at its
    /// quaternion `ξ_root` and, across each joint, from the first end's node rotated by the
    /// joint's relative rotation `ξ_j` (`ξ_b = ξ_a ⊗ ξ_j`). Beams are rebuilt from their start
    /// node, reached through the support or a joint's second end (every two-link of the
    /// paper).
    pub fn configuration(
        &self,
        structure: &Structure,
        layout: &modal_rom::Layout,
        root: usize,
    ) -> Result<(Vec<f64>, Vec<Kinematics>)> {
        let rom = &self.rom;
        let q1 = rom.link_velocities(&self.x)?;
        let (phi1, phi2) = (rom.basis().phi1(), rom.basis().phi2());
        let p2 = &self.x[rom.n_p()..rom.n_p() + rom.n_p2()];
        let mut x = vec![0.0; layout.n_full()];
        for (i, v) in x.iter_mut().enumerate() {
            match layout.classify_full(i) {
                FullIndex::X1(r) => *v = (0..q1.len()).map(|c| phi1[(r, c)] * q1[c]).sum(),
                FullIndex::X2(r) => *v = (0..p2.len()).map(|c| phi2[(r, c)] * p2[c]).sum(),
                _ => {}
            }
        }
        let beams = structure.beams();
        let state = |b: usize| {
            let o = layout.full_offset(b);
            &x[o..o + beams[b].beam.dim()]
        };
        let reference = structure.reference();
        let mut kin: Vec<Option<Kinematics>> = vec![None; beams.len()];
        let joints = structure.joints();
        let start_only = |what: &str, name: &str| {
            invalid(
                format!("{what} `{name}`"),
                "end node",
                "the exact-joints plant rebuilds each beam from its start node",
            )
        };
        let (rb, re) = joints[root].ends[0];
        let rn = structure.end_node(rb, re);
        if rn != 0 {
            return Err(start_only("support", &joints[root].name));
        }
        let xi_root = rom.root_quaternion(&self.x).unwrap_or(reference[rb].xi[rn]);
        kin[rb] = Some(
            Kinematics::from_strains(&beams[rb].beam, state(rb), xi_root, reference[rb].r[rn])
                .map_err(beam_error)?,
        );
        let names = rom.joint_names();
        for _ in 0..joints.len() {
            for (j, name) in names.iter().enumerate() {
                let Some(info) = joints.iter().find(|i| &i.name == name) else { continue };
                let ((ba, ea), (bb, eb)) = (info.ends[0], info.ends[1]);
                if kin[bb].is_some() {
                    continue;
                }
                let Some(ka) = &kin[ba] else { continue };
                if structure.end_node(bb, eb) != 0 {
                    return Err(start_only("joint", name));
                }
                let na = structure.end_node(ba, ea);
                let xi_b = quat_mul(&ka.xi[na], &rom.joint_quaternion(&self.x, j));
                let r_b = ka.r[na];
                let k = Kinematics::from_strains(&beams[bb].beam, state(bb), xi_b, r_b);
                kin[bb] = Some(k.map_err(beam_error)?);
            }
        }
        let kin = kin
            .into_iter()
            .enumerate()
            .map(|(b, k)| {
                k.ok_or_else(|| {
                    invalid(
                        format!("beam {b}"),
                        "unreached",
                        "no joint chain from the root support",
                    )
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok((x, kin))
    }
}
