//! The plants a controller acts on: the constrained FE model (multibody-constraints) or the
//! modal model itself, with the inputs defined once for both.

use crate::dynamics::RomDynamics;
use crate::error::{invalid, MpcError, Result};
use intrinsic_beam::rotation::{quat_conj, quat_mul};
use intrinsic_beam::{Amplitude, LoadFrame, PointLoad};
use modal_rom::{Input, ModalRom, StructureModel};
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
    /// The augmented modal model itself (fast studies; no model mismatch).
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
        }
    }
}
