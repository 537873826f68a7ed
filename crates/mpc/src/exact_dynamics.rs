//! The exact-joints reduced model (theory.md §10) as an [`ocp_transcription::Dynamics`], its
//! cost, and the choice between the paper's model and it ([`ModelKind`]).
//!
//! State `x = [p, p2, ξ_root, ξ_j…]` (see [`modal_rom::ExactJointsRom`]). The cost measures the
//! root link's orientation and each joint's relative rotation directly from the quaternion
//! states, against references that may be any rotations (non-zero joint angles):
//!
//! ```text
//!   V = kx1 |p|² + kx2 |p2|² + k_root |ξ_root − ξ_root,r|² + Σ_j k_j |ξ_j − ξ_j,r|² + ku |u|²   (×½)
//! ```
//!
//! with the paper's weights mapped as follows: `kx1`, `kx2`, `ku` as in (35); for a rigid
//! structure the paper's `Kξᵀ Aξ Kξ` term (rigid weight `k_xi_rigid`) is the length-weighted
//! squared quaternion error of every link, so `k_root = k_xi_rigid · (total length)` and the
//! joint's share `k_xi_rigid · (length outboard of the joint)`, to which the jump penalty (36)
//! adds `k_dxi` (`|ξ_a − ξ_b|² = |ξ_j − 1|²` for unit quaternions).

use crate::error::{invalid, Result};
use crate::weights::{MpcSettings, Weights};
use modal_rom::StructureModel;
use modal_rom::{BasisSettings, ExactJointsRom, Input, LinkBasisSettings, ModeSelection};
use multibody_constraints::Structure;
use nalgebra::{DMatrix, DVector, Vector4};
use ocp_transcription::Dynamics;
use serde::{Deserialize, Serialize};

/// Which reduced model the controller uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// The paper's model (14)–(29), modes and joint rows linearised at the reference angle.
    #[default]
    Paper,
    /// The exact-joints model (theory.md §10): joint rows at the current relative rotation.
    ExactJoints,
}

impl ModelKind {
    /// `paper` or `exact-joints`.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Paper => "paper",
            ModelKind::ExactJoints => "exact-joints",
        }
    }

    /// Parses `paper` / `exact-joints`.
    pub fn parse(text: &str) -> Result<Self> {
        match text.trim() {
            "paper" => Ok(ModelKind::Paper),
            "exact-joints" => Ok(ModelKind::ExactJoints),
            other => Err(invalid("model", other, "must be `paper` or `exact-joints`")),
        }
    }
}

/// [`ExactJointsRom`] as OCP dynamics, with its exact Jacobian (theory.md §10.5). A state outside
/// the model's range (joint rotation the fields cannot represent) yields NaN, which the SQP
/// treats as a failed trial point.
#[derive(Clone, Debug)]
pub struct ExactDynamics {
    rom: ExactJointsRom,
    linear: DMatrix<f64>,
}

impl ExactDynamics {
    /// Wraps `rom`; its linear part (for Lawson integrators) is the Jacobian at the reference.
    pub fn new(rom: ExactJointsRom) -> Result<Self> {
        if rom.n_inputs() == 0 {
            return Err(invalid("rom inputs", 0, "the controller model needs at least one input"));
        }
        let n = rom.n_state();
        let nu = rom.n_inputs();
        let x = rom.reference_state();
        let (mut f, mut jx, mut ju) = (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]);
        rom.rhs_and_jacobian(&x, &vec![0.0; nu], &mut f, &mut jx, &mut ju).map_err(|e| {
            invalid("exact-joints model at the reference", e.to_string(), "must evaluate")
        })?;
        Ok(Self { rom, linear: DMatrix::from_column_slice(n, n, &jx) })
    }

    /// The wrapped model.
    pub fn rom(&self) -> &ExactJointsRom {
        &self.rom
    }

    /// The cost of the module docs with the paper's weights `settings`; `link_lengths[b]` the
    /// lengths of the links, `outboard[j]` the total length outboard of joint `j`, and
    /// references `root_ref` (None: the reference state's) and `joint_refs` (None: the
    /// reference state's).
    pub fn weights(
        &self,
        settings: &MpcSettings,
        total_length: f64,
        outboard: &[f64],
        root_ref: Option<Vector4<f64>>,
        joint_refs: &[Option<Vector4<f64>>],
    ) -> Result<Weights> {
        settings.validate()?;
        let rom = &self.rom;
        let n = rom.n_state();
        if outboard.len() != rom.n_joints() || joint_refs.len() != rom.n_joints() {
            return Err(invalid(
                "outboard / joint_refs",
                format!("{} / {}", outboard.len(), joint_refs.len()),
                format!("one per joint ({})", rom.n_joints()),
            ));
        }
        let mut q = DMatrix::zeros(n, n);
        for i in 0..rom.n_p() {
            q[(i, i)] = settings.cost.kx1;
        }
        for i in 0..rom.n_p2() {
            let k = rom.n_p() + i;
            q[(k, k)] = settings.cost.kx2;
        }
        let mut x_ref = rom.reference_state();
        if rom.has_root() {
            let o = rom.root_offset();
            for i in 0..4 {
                q[(o + i, o + i)] = settings.cost.k_xi_rigid * total_length;
            }
            if let Some(r) = root_ref {
                x_ref[o..o + 4].copy_from_slice(r.as_slice());
            }
        }
        for j in 0..rom.n_joints() {
            let o = rom.joint_offset(j);
            for i in 0..4 {
                q[(o + i, o + i)] = settings.cost.k_xi_rigid * outboard[j] + settings.cost.k_dxi;
            }
            if let Some(r) = joint_refs[j] {
                x_ref[o..o + 4].copy_from_slice(r.as_slice());
            }
        }
        let nu = rom.n_inputs();
        Ok(Weights {
            q,
            r: DMatrix::identity(nu, nu) * settings.cost.ku,
            x_ref: DVector::from_vec(x_ref),
            k_xi: Vec::new(),
            a_xi: DMatrix::zeros(0, 0),
            a_dxi: DMatrix::zeros(0, 0),
        })
    }
}

/// Default of [`crate::ControllerSettings::link_elastic_modes`]: 4 elastic modes per link for
/// planar, 16 for spatial structures (docs/exact-joints-results.md).
pub fn default_link_elastic_modes(spatial: bool) -> usize {
    if spatial {
        16
    } else {
        4
    }
}

/// The exact-joints model of `structure`: per-link basis of the rigid link motions plus the
/// lowest `elastic` constrained modes at the reference split per link (theory.md §10.7), the
/// structure's damping, the inputs `inputs`.
pub fn exact_joints_rom(
    structure: &Structure,
    model: &StructureModel,
    elastic: usize,
    inputs: &[Input],
) -> Result<ExactJointsRom> {
    let modes = model.modes(&BasisSettings::default())?;
    let sel = modes.select(&ModeSelection::Lowest(modes.n_rigid() + elastic))?;
    Ok(modal_rom::exact_joints::from_fields(
        structure,
        model,
        &[sel.phi1()],
        &LinkBasisSettings::default(),
        Some(&model.damping),
        inputs,
    )?)
}

impl ExactDynamics {
    /// The exact-joints controller model of a scenario's setup: per-link basis of the rigid link
    /// motions plus the lowest `elastic` constrained modes at the reference split per link, the
    /// structure's damping and the scenario's inputs; with the cost of the module docs at the
    /// reference state. The joints' outboard lengths assume the beams are ordered from the root
    /// outward along a chain (every scenario of the paper).
    pub fn for_setup(setup: &crate::Setup, elastic: usize) -> Result<(Self, Weights)> {
        let sc = &setup.scenario;
        let structure = &sc.structure;
        let model = &setup.model;
        let inputs =
            sc.inputs.iter().map(|i| i.modal(structure, model)).collect::<Result<Vec<_>>>()?;
        let rom = exact_joints_rom(structure, model, elastic, &inputs)?;
        let lengths: Vec<f64> = structure.beams().iter().map(|b| b.beam.mesh().length()).collect();
        let total: f64 = lengths.iter().sum();
        let outboard: Vec<f64> = structure
            .joints()
            .iter()
            .filter(|j| !j.ground && j.ends.len() == 2)
            .map(|j| {
                let child = j.ends.iter().map(|&(b, _)| b).max().unwrap_or(0);
                lengths[child..].iter().sum()
            })
            .collect();
        let dynamics = Self::new(rom)?;
        let refs = vec![None; outboard.len()];
        let weights = dynamics.weights(&sc.mpc, total, &outboard, None, &refs)?;
        Ok((dynamics, weights))
    }
}

impl ExactDynamics {
    /// The reference schedule of the scenario's joint commands ([`crate::reference`]) on the
    /// reference state of `weights`: a command on a two-end joint sets that joint's
    /// relative-rotation state `ξ_j`, one on the root support the root quaternion `ξ_root`.
    pub fn reference_schedule(
        &self,
        setup: &crate::Setup,
        weights: &Weights,
    ) -> Result<crate::ReferenceSchedule> {
        let rom = &self.rom;
        let names = rom.joint_names();
        let mut slots = Vec::new();
        for (i, c) in setup.scenario.references.iter().enumerate() {
            let (nodes, base) = crate::reference::command_target(
                &setup.joint_names,
                &setup.joint_nodes,
                &setup.reference_xi,
                c,
            )
            .map_err(|e| e.within(&format!("references[{i}]")))?;
            let offset = match nodes.len() {
                1 if c.joint == setup.scenario.root && rom.has_root() => rom.root_offset(),
                2 => match names.iter().position(|n| *n == c.joint) {
                    Some(j) => rom.joint_offset(j),
                    None => {
                        return Err(invalid(
                            format!("references[{i}].joint"),
                            &c.joint,
                            "has no rotation state in the exact-joints model",
                        ))
                    }
                },
                _ => {
                    return Err(invalid(
                        format!("references[{i}].joint"),
                        &c.joint,
                        "commands act on the root support or on joints between links",
                    ))
                }
            };
            slots.push((offset, c.clone(), base));
        }
        crate::ReferenceSchedule::new(weights.x_ref.iter().copied().collect(), slots)
    }
}

impl Dynamics for ExactDynamics {
    fn nx(&self) -> usize {
        self.rom.n_state()
    }

    fn nu(&self) -> usize {
        self.rom.n_inputs()
    }

    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
        if self.rom.rhs(x, u, xdot).is_err() {
            xdot.fill(f64::NAN);
        }
    }

    fn jacobians(&self, x: &[f64], u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        let mut f = vec![0.0; self.nx()];
        self.rhs_and_jacobians(x, u, &mut f, fx, fu);
    }

    fn rhs_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        xdot: &mut [f64],
        fx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) {
        if self.rom.rhs_and_jacobian(x, u, xdot, fx.as_mut_slice(), fu.as_mut_slice()).is_err() {
            xdot.fill(f64::NAN);
            fx.fill(f64::NAN);
            fu.fill(f64::NAN);
        }
    }

    fn linear_part(&self) -> Option<DMatrix<f64>> {
        Some(self.linear.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use intrinsic_beam::Section;
    use modal_rom::{
        exact_joints, BasisSettings, LinkBasisSettings, ModeSelection, StructureModel,
    };
    use ocp_transcription::{SqpSettings, SqpSolver};

    fn model_2d(n: usize) -> (ExactDynamics, multibody_constraints::Structure) {
        let s = multibody_constraints::samples::paper_2d(Section::paper_2d(), n, 0.0).unwrap();
        let m = StructureModel::new(&s).unwrap();
        let b = m.modes(&BasisSettings::default()).unwrap();
        let sel = b.select(&ModeSelection::Lowest(b.n_rigid() + 4)).unwrap();
        let inputs = modal_rom::samples::inputs_2d(&s, &m).unwrap();
        let rom = exact_joints::from_fields(
            &s,
            &m,
            &[sel.phi1()],
            &LinkBasisSettings::default(),
            Some(&m.damping),
            &inputs,
        )
        .unwrap();
        (ExactDynamics::new(rom).unwrap(), s)
    }

    #[test]
    fn model_kind_parses_and_defaults_to_paper() {
        assert_eq!(ModelKind::default(), ModelKind::Paper);
        assert_eq!(ModelKind::parse("exact-joints").unwrap(), ModelKind::ExactJoints);
        assert_eq!(ModelKind::parse(ModelKind::Paper.name()).unwrap(), ModelKind::Paper);
        assert!(ModelKind::parse("exact").unwrap_err().to_string().contains("model"));
    }

    /// The adapter's Jacobian against central differences at a state with the elbow at 70°.
    #[test]
    fn adapter_jacobian_matches_finite_differences() {
        let (d, _) = model_2d(6);
        let (n, nu) = (d.nx(), d.nu());
        let mut x = d.rom().reference_state();
        for (i, v) in x[..d.rom().n_p() + d.rom().n_p2()].iter_mut().enumerate() {
            *v = 0.2 * (0.9 * i as f64 + 0.4).sin();
        }
        let o = d.rom().joint_offset(0);
        let a = 70f64.to_radians();
        x[o..o + 4].copy_from_slice(&[(0.5 * a).cos(), 0.0, (0.5 * a).sin(), 0.0]);
        let u = vec![0.5, -0.2, 0.3];
        let (mut fx, mut fu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, nu));
        d.jacobians(&x, &u, &mut fx, &mut fu);
        let h = 1e-6;
        let (mut fp, mut fm) = (vec![0.0; n], vec![0.0; n]);
        let scale = fx.amax().max(1.0);
        let mut worst = 0.0f64;
        for c in 0..n + nu {
            let (mut xp, mut xm, mut up, mut um) = (x.clone(), x.clone(), u.clone(), u.clone());
            if c < n {
                xp[c] += h;
                xm[c] -= h;
            } else {
                up[c - n] += h;
                um[c - n] -= h;
            }
            d.rhs(&xp, &up, &mut fp);
            d.rhs(&xm, &um, &mut fm);
            for r in 0..n {
                let an = if c < n { fx[(r, c)] } else { fu[(r, c - n)] };
                worst = worst.max(((fp[r] - fm[r]) / (2.0 * h) - an).abs() / scale);
            }
        }
        assert!(worst < 1e-7, "adapter Jacobian vs FD: {worst:e}");
    }

    /// One OCP from a spin ω0 = 1 about the root with the paper's weights and horizon: within
    /// 15 SQP iterations (Lawson RK4, the controller's integrator) the plan stops the spin and
    /// restores the orientation (state cost at the end of the horizon ≤ 5 % of the initial).
    #[test]
    fn ocp_from_a_spin_plans_to_stop_it() {
        let (d, s) = model_2d(6);
        let settings = MpcSettings::default();
        let w = d.weights(&settings, 2.0, &[1.0], None, &[None]).unwrap();
        let x_fe = s.rigid_rotation_state(
            nalgebra::Vector3::new(0.0, 1.0, 0.0),
            nalgebra::Vector3::zeros(),
        );
        let x0 = d.rom().project_fe(&x_fe, s.reference()).unwrap();
        let (nx, nu) = (d.nx(), d.nu());
        let ocp = w.ocp(&settings, nx, nu).unwrap();
        let sqp = SqpSettings {
            integrator: crate::ControllerSettings::default().integrator,
            levenberg_marquardt: crate::ControllerSettings::default().levenberg_marquardt,
            max_iterations: 15,
            ..SqpSettings::default()
        };
        let mut solver = SqpSolver::new(d, ocp, sqp).unwrap();
        solver.initialize_constant(&x0, &vec![0.0; nu]).unwrap();
        let stats = solver.solve(&x0).unwrap();
        let v0 = w.state_cost(&x0);
        let last = solver.states().last().unwrap().clone();
        let v_end = w.state_cost(last.as_slice());
        eprintln!(
            "SQP {:?}: {} iterations, V(x0) {v0:.3e}, V(x_N) {v_end:.3e}",
            stats.status, stats.iterations
        );
        assert!(v_end < 0.05 * v0, "the plan should stop the spin: {v_end:e} vs {v0:e}");
    }
}
