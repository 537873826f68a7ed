//! The constrained FE plant: implicit-midpoint DAE with joints as hard constraints.
//!
//! Unknowns per step: the global vector at `t + dt` (beams' `x1`, `x2`, and the end values,
//! which hold the step's midpoint reactions). Rows: every beam's `k(2N+1)` midpoint rows
//! ([`intrinsic_beam::Beam::step_residual`]) and the joint, support and free-end rows of
//! [`crate::joint`] evaluated at the midpoint, with one rotation per end,
//! `T_j = T(exp(dt/2 U(ω_mid)) ξ_n)` — the same rotation the beam uses for dead loads and the
//! kinematics for `r⁺ = r + dt T_mid v_mid`. Hence the joints' discrete power cancels exactly
//! (energy is conserved to solver tolerance) and joined ends move by identical increments (no
//! gap drift). Newton with faer's sparse LU (fixed symbolic factorisation); the `T`-dependence
//! of the joint rows enters the Jacobian by central differences in `ω_mid`.

use faer::Mat;
use intrinsic_beam::operators::halves;
use intrinsic_beam::rotation::{quat_conj, quat_mul, quaternion_step, rotation, rotation_angle};
use intrinsic_beam::SparseLuSystem;
use intrinsic_beam::{Kinematics, LoadFrame, Loads, StepInput};
use nalgebra::{Matrix3, Vector3, Vector4, Vector6};
use serde::{Deserialize, Serialize};

use crate::error::{MultibodyError, Result};
use crate::joint::{rows, RowKind};
use crate::structure::{end_load_global, JointInfo, Structure};

/// Settings of the plant's time stepping.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantSettings {
    /// Time step (s), > 0. Default `1e-3`.
    pub dt: f64,
    /// Newton stops when the update's max-norm is below `newton_tolerance · max(1, |x|∞)`.
    /// Default `1e-12` (energy drift over 10⁴ steps stays below 1e-10).
    pub newton_tolerance: f64,
    /// Newton iteration limit per step (≥ 1). Default 25.
    pub max_newton_iterations: usize,
    /// Relative step of the central differences in `ω_mid` for `∂T/∂ω` (default `1e-6`).
    pub fd_step: f64,
    /// Start Newton from the quadratic extrapolation `3 x_n − 3 x_{n−1} + x_{n−2}` of the
    /// last states (default `true`).
    pub extrapolate: bool,
    /// Keep the factorised Jacobian across iterations and steps while Newton contracts by at
    /// least 20× per iteration (default `true`); `false`: full Newton.
    pub reuse_jacobian: bool,
}

impl Default for PlantSettings {
    fn default() -> Self {
        Self {
            dt: 1e-3,
            newton_tolerance: 1e-12,
            max_newton_iterations: 25,
            fd_step: 1e-6,
            extrapolate: true,
            reuse_jacobian: true,
        }
    }
}

impl PlantSettings {
    /// Checks the ranges documented on each field.
    pub fn validate(&self) -> Result<()> {
        let bad = |field, value, reason| Err(MultibodyError::BadSetting { field, value, reason });
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return bad("dt", self.dt, "must be positive and finite");
        }
        if !(self.newton_tolerance > 0.0 && self.newton_tolerance < 1.0) {
            return bad("newton_tolerance", self.newton_tolerance, "must be in (0, 1)");
        }
        if self.max_newton_iterations == 0 {
            return bad("max_newton_iterations", 0.0, "must be at least 1");
        }
        if !(self.fd_step > 0.0 && self.fd_step < 1e-2) {
            return bad("fd_step", self.fd_step, "must be in (0, 1e-2)");
        }
        Ok(())
    }
}

/// The loads a joint applies on its ends over a run ([`Plant::run_joint_balance`]), each the
/// largest over the steps.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointBalance {
    /// Norm of the sum of the end forces (zero in balance, eq. 12).
    pub force_sum: f64,
    /// Norm of an end moment (zero for a ball joint).
    pub moment: f64,
    /// Norm of an end load `[force, moment]`: the load scale.
    pub load_scale: f64,
    /// Velocity-compatibility violation of a step ([`StepReport::velocity_violation`]).
    pub velocity_violation: f64,
}

/// What one step did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Newton iterations.
    pub iterations: usize,
    /// Jacobian factorisations in this step.
    pub factorizations: usize,
    /// Last Newton update (max-norm, relative).
    pub update: f64,
    /// Largest violation of a compatibility row at the midpoint (velocity units).
    pub velocity_violation: f64,
    /// Largest violation of a balance row at the midpoint (force units).
    pub balance_violation: f64,
    /// Power of all joints and supports on the beams at the midpoint, `Σ −σ_j x1_j·y_j`
    /// (zero for passive joints; joint torques times relative rates otherwise).
    pub joint_power: f64,
}

/// An applied joint torque: joint index, active axis, value.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Torque {
    joint: usize,
    axis: usize,
    value: f64,
}

/// The constrained plant: a structure, its state and kinematics, inputs, and the Newton
/// workspace (built once; no symbolic work per step).
pub struct Plant {
    structure: Structure,
    settings: PlantSettings,
    time: f64,
    state: Vec<f64>,
    previous: Option<Vec<f64>>,
    previous2: Option<Vec<f64>>,
    kinematics: Vec<Kinematics>,
    loads: Vec<Loads>,
    gravity: Vector3<f64>,
    torques: Vec<Torque>,
    // workspace
    step_loads: Vec<Loads>,
    row_of_constraint: Vec<usize>,
    beam_nnz: Vec<(usize, usize)>,
    joint_nnz: Vec<usize>,
    free_nnz: usize,
    values: Vec<f64>,
    /// Step matrix with its fixed pattern; `factorized` says whether its last numeric LU is
    /// that of the current step's Jacobian (reusable).
    lu: SparseLuSystem,
    factorized: bool,
    rhs: Vec<f64>,
    mid: Vec<f64>,
    weight: Vec<f64>,
    residual: Vec<f64>,
    /// Midpoint rotations of every joint end at the last step.
    end_rotations: Vec<Vec<Matrix3<f64>>>,
    angles: Vec<f64>,
    last: StepReport,
    steps: usize,
}

impl Plant {
    /// A plant at rest in the reference configuration. Checks the settings and the
    /// constraints' rank (redundant or conflicting constraints are an error naming them).
    ///
    /// ```
    /// use intrinsic_beam::Section;
    /// use multibody_constraints::{samples, Plant, PlantSettings};
    ///
    /// // the paper's 2D two-link, 4 elements per link, released at rest: it stays at rest
    /// let structure = samples::paper_2d(Section::paper_2d(), 4, 0.0)?;
    /// let mut plant = Plant::new(structure, PlantSettings::default())?;
    /// plant.step()?;
    /// assert!(plant.energy().abs() < 1e-20);
    /// # Ok::<(), multibody_constraints::MultibodyError>(())
    /// ```
    pub fn new(structure: Structure, settings: PlantSettings) -> Result<Self> {
        settings.validate()?;
        let dim = structure.dim();
        let n_beams = structure.beams().len();
        let k = structure.k();
        // Constraint rows go to the end-unknown rows of each beam (beam row i ↔ unknown i).
        let mut row_of_constraint = Vec::with_capacity(structure.n_constraint_rows());
        for b in 0..n_beams {
            let beam = &structure.beams()[b].beam;
            let o = structure.offset(b) + beam.n_rows();
            row_of_constraint.extend(o..o + 2 * k);
        }
        // Pattern.
        let mut pattern: Vec<(usize, usize)> = Vec::new();
        let mut beam_nnz = Vec::with_capacity(n_beams);
        for b in 0..n_beams {
            let beam = &structure.beams()[b].beam;
            let start = pattern.len();
            beam.jacobian_pattern(structure.offset(b), structure.offset(b), &mut pattern);
            beam_nnz.push((start, pattern.len() - start));
        }
        let mut joint_nnz = Vec::new();
        for j in structure.joints() {
            joint_nnz.push(pattern.len());
            let slots = structure.joint_slots(j);
            for r in 0..j.n_rows {
                for &c in &slots {
                    pattern.push((row_of_constraint[j.first_row + r], c));
                }
            }
        }
        let free_nnz = pattern.len();
        for &(b, e, r0) in structure.free_ends() {
            for a in 0..k {
                pattern.push((row_of_constraint[r0 + a], structure.x2_end_column(b, e, a)));
            }
        }
        let lu = SparseLuSystem::new(dim, &pattern)?;
        let mut weight = vec![1.0; dim];
        for b in 0..n_beams {
            let beam = &structure.beams()[b].beam;
            for i in 0..beam.dim() {
                weight[structure.offset(b) + i] = beam.midpoint_weight(i);
            }
        }
        let kinematics = structure.reference().to_vec();
        let angles = vec![0.0; structure.joints().len()];
        let end_rotations = structure
            .joints()
            .iter()
            .map(|j| {
                j.ends
                    .iter()
                    .map(|&(b, e)| rotation(&kinematics[b].xi[structure.end_node(b, e)]))
                    .collect()
            })
            .collect();
        let mut plant = Self {
            settings,
            time: 0.0,
            state: vec![0.0; dim],
            previous: None,
            previous2: None,
            loads: vec![Loads::none(); n_beams],
            step_loads: vec![Loads::none(); n_beams],
            gravity: Vector3::zeros(),
            torques: Vec::new(),
            row_of_constraint,
            beam_nnz,
            joint_nnz,
            free_nnz,
            values: vec![0.0; pattern.len()],
            lu,
            factorized: false,
            rhs: vec![0.0; dim],
            mid: vec![0.0; dim],
            weight,
            residual: vec![0.0; dim],
            end_rotations,
            angles,
            last: StepReport::default(),
            steps: 0,
            kinematics,
            structure,
        };
        plant.angles = plant.compute_angles(None);
        plant.check_rank()?;
        Ok(plant)
    }

    /// The structure.
    pub fn structure(&self) -> &Structure {
        &self.structure
    }

    /// The settings.
    pub fn settings(&self) -> &PlantSettings {
        &self.settings
    }

    /// Current time.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Number of steps taken.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Current global state vector.
    pub fn state(&self) -> &[f64] {
        &self.state
    }

    /// Node kinematics of every beam.
    pub fn kinematics(&self) -> &[Kinematics] {
        &self.kinematics
    }

    /// The last step's report.
    pub fn last_report(&self) -> StepReport {
        self.last
    }

    /// Replaces the state (e.g. an initial velocity field); the kinematics stay.
    pub fn set_state(&mut self, x: &[f64]) -> Result<()> {
        if x.len() != self.state.len() {
            return Err(MultibodyError::BadInput {
                input: "state".into(),
                reason: format!("length {} but the structure has {}", x.len(), self.state.len()),
            });
        }
        if let Some((i, v)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(MultibodyError::NotFinite { what: format!("state entry {i}"), value: *v });
        }
        self.state.copy_from_slice(x);
        self.previous = None;
        self.previous2 = None;
        Ok(())
    }

    /// Replaces the kinematics (node quaternions and positions) of every beam.
    pub fn set_kinematics(&mut self, kinematics: Vec<Kinematics>) -> Result<()> {
        if kinematics.len() != self.kinematics.len()
            || kinematics
                .iter()
                .zip(&self.kinematics)
                .any(|(a, b)| a.xi.len() != b.xi.len() || a.r.len() != b.r.len())
        {
            return Err(MultibodyError::BadInput {
                input: "kinematics".into(),
                reason: "sizes differ from the structure's".into(),
            });
        }
        self.kinematics = kinematics;
        self.angles = self.compute_angles(None);
        Ok(())
    }

    /// The loads of beam `b` (point/distributed, follower/dead), to change between steps.
    pub fn loads_mut(&mut self, b: usize) -> &mut Loads {
        &mut self.loads[b]
    }

    /// The loads of beam `b`.
    pub fn loads(&self, b: usize) -> &Loads {
        &self.loads[b]
    }

    /// Sets gravity (global acceleration vector, e.g. `[0, 0, −9.81]`); checked per beam.
    pub fn set_gravity(&mut self, g: Vector3<f64>) -> Result<()> {
        if g.iter().any(|v| !v.is_finite()) {
            return Err(MultibodyError::NotFinite { what: "gravity".into(), value: g.norm() });
        }
        for b in 0..self.structure.beams().len() {
            self.structure.gravity_load(b, &g)?;
        }
        self.gravity = g;
        Ok(())
    }

    /// Gravity.
    pub fn gravity(&self) -> Vector3<f64> {
        self.gravity
    }

    /// Sets the torque about a free rotation axis of a joint or support (`axis` indexes the
    /// joint's active axes; `None` picks its only free rotation axis). For a two-end joint,
    /// `+τ` acts on the second end and `−τ` on the first; for a support, `+τ` on the end.
    pub fn set_joint_torque(&mut self, joint: &str, axis: Option<usize>, value: f64) -> Result<()> {
        let bad = |reason: String| MultibodyError::BadInput {
            input: format!("torque at `{joint}`"),
            reason,
        };
        if !value.is_finite() {
            return Err(MultibodyError::NotFinite { what: format!("torque at `{joint}`"), value });
        }
        let ji = self
            .structure
            .joint_index(joint)
            .ok_or_else(|| bad("unknown joint or support".into()))?;
        let j = &self.structure.joints()[ji];
        if !j.ground && j.ends.len() != 2 {
            return Err(bad(format!(
                "torques need a two-end joint or a support; it has {} ends",
                j.ends.len()
            )));
        }
        let axis = j.free_rotation_axis(axis)?;
        if let Some(t) = self.torques.iter_mut().find(|t| t.joint == ji && t.axis == axis) {
            t.value = value;
        } else {
            self.torques.push(Torque { joint: ji, axis, value });
        }
        Ok(())
    }

    /// Kinetic plus elastic energy (eq. 6, discrete), summed over beams.
    pub fn energy(&self) -> f64 {
        (0..self.structure.beams().len())
            .map(|b| {
                self.structure.beams()[b]
                    .beam
                    .energy(self.structure.beam_slice(b, &self.state))
                    .unwrap_or(f64::NAN)
            })
            .sum()
    }

    /// Potential energy of gravity, `−Σ w_n m g·r_n`.
    pub fn potential_energy(&self) -> f64 {
        let mut v = 0.0;
        for (b, sb) in self.structure.beams().iter().enumerate() {
            let m = self.structure.mass_per_length(b);
            for (n, w) in sb.beam.mesh().weights().iter().enumerate() {
                v -= w * m * self.gravity.dot(&self.kinematics[b].r[n]);
            }
        }
        v
    }

    fn torques_of(&self, ji: usize) -> Vec<f64> {
        let mut tau = vec![0.0; self.structure.joints()[ji].axes.len()];
        for t in self.torques.iter().filter(|t| t.joint == ji) {
            tau[t.axis] = t.value;
        }
        tau
    }

    fn prepare_loads(&mut self) -> Result<()> {
        for b in 0..self.loads.len() {
            let l = &mut self.step_loads[b];
            l.point.clone_from(&self.loads[b].point);
            l.distributed.clone_from(&self.loads[b].distributed);
            if self.gravity != Vector3::zeros() {
                let g = self.structure.gravity_load(b, &self.gravity)?;
                l.distributed.push(intrinsic_beam::DistributedLoad {
                    frame: LoadFrame::Dead,
                    value: g,
                    amplitude: intrinsic_beam::Amplitude::Constant,
                });
            }
        }
        Ok(())
    }

    /// Midpoint rotation of each end of joint `j` from `mid`, with optional `ω` perturbation
    /// `(end, component 0..3, delta)`.
    fn joint_rotations(
        &self,
        j: &JointInfo,
        mid: &[f64],
        perturb: Option<(usize, usize, f64)>,
    ) -> Vec<Matrix3<f64>> {
        let half = 0.5 * self.settings.dt;
        j.ends
            .iter()
            .enumerate()
            .map(|(je, &(b, e))| {
                let x1 = self.structure.end_velocity(mid, b, e);
                let (_, mut w) = halves(&x1);
                if let Some((pe, pc, d)) = perturb {
                    if pe == je {
                        w[pc] += d;
                    }
                }
                rotation(&quaternion_step(
                    &self.kinematics[b].xi[self.structure.end_node(b, e)],
                    &w,
                    half,
                ))
            })
            .collect()
    }

    fn compute_mid(&mut self, old: &[f64], new: &[f64]) -> Result<()> {
        for (b, sb) in self.structure.beams().iter().enumerate() {
            let (o, d) = (self.structure.offset(b), sb.beam.dim());
            sb.beam.midpoint(&old[o..o + d], &new[o..o + d], &mut self.mid[o..o + d])?;
        }
        Ok(())
    }

    /// Residual of the whole step system at `new` (uses `self.mid`, which must be current).
    fn assemble_residual(&mut self, old: &[f64], new: &[f64]) -> Result<()> {
        let dt = self.settings.dt;
        for (b, sb) in self.structure.beams().iter().enumerate() {
            let (o, d, nr) = (self.structure.offset(b), sb.beam.dim(), sb.beam.n_rows());
            let input = StepInput {
                time: self.time,
                dt,
                loads: &self.step_loads[b],
                node_quaternions: &self.kinematics[b].xi,
            };
            sb.beam.step_residual(
                &input,
                &old[o..o + d],
                &new[o..o + d],
                &mut self.residual[o..o + nr],
            )?;
        }
        let k = self.structure.k();
        for (ji, j) in self.structure.joints().iter().enumerate() {
            let rot = self.joint_rotations(j, &self.mid, None);
            let slots = self.structure.joint_slots(j);
            let ns = slots.len();
            let mut coef = vec![0.0; j.n_rows * ns];
            self.structure.joint_coefficients(j, &rot, &mut coef);
            let mut rhs = vec![0.0; j.n_rows];
            self.structure.joint_rhs(j, &self.torques_of(ji), &mut rhs);
            for r in 0..j.n_rows {
                let mut v = -rhs[r];
                for (s, &c) in slots.iter().enumerate() {
                    v += coef[r * ns + s] * self.mid[c];
                }
                self.residual[self.row_of_constraint[j.first_row + r]] = v;
            }
        }
        for &(b, e, r0) in self.structure.free_ends() {
            for a in 0..k {
                self.residual[self.row_of_constraint[r0 + a]] =
                    self.mid[self.structure.x2_end_column(b, e, a)];
            }
        }
        if self.residual.iter().any(|v| !v.is_finite()) {
            return Err(MultibodyError::NotFinite {
                what: format!("step residual at t = {}", self.time),
                value: f64::NAN,
            });
        }
        Ok(())
    }

    /// Jacobian values at `new` (uses `self.mid`).
    fn assemble_jacobian(&mut self, old: &[f64], new: &[f64]) -> Result<()> {
        let dt = self.settings.dt;
        for (b, sb) in self.structure.beams().iter().enumerate() {
            let (o, d) = (self.structure.offset(b), sb.beam.dim());
            let input = StepInput {
                time: self.time,
                dt,
                loads: &self.step_loads[b],
                node_quaternions: &self.kinematics[b].xi,
            };
            let (start, len) = self.beam_nnz[b];
            sb.beam.jacobian_values(
                &input,
                &old[o..o + d],
                &new[o..o + d],
                &mut self.values[start..start + len],
            )?;
        }
        let k = self.structure.k();
        let idx = self.structure.components().indices();
        for (ji, j) in self.structure.joints().iter().enumerate() {
            let slots = self.structure.joint_slots(j);
            let ns = slots.len();
            let rot = self.joint_rotations(j, &self.mid, None);
            let mut coef = vec![0.0; j.n_rows * ns];
            self.structure.joint_coefficients(j, &rot, &mut coef);
            let start = self.joint_nnz[ji];
            for r in 0..j.n_rows {
                for (s, &c) in slots.iter().enumerate() {
                    self.values[start + r * ns + s] = coef[r * ns + s] * self.weight[c];
                }
            }
            // ∂T/∂ω_mid by central differences (only frames that rotate with the ends).
            let mut plus = vec![0.0; j.n_rows * ns];
            let mut minus = vec![0.0; j.n_rows * ns];
            for je in 0..j.ends.len() {
                for a in 0..k {
                    if idx[a] < 3 {
                        continue;
                    }
                    let comp = idx[a] - 3;
                    let col_slot = je * 2 * k + a;
                    let w = self.mid[slots[col_slot]];
                    let delta = self.settings.fd_step * w.abs().max(1.0);
                    let rp = self.joint_rotations(j, &self.mid, Some((je, comp, delta)));
                    let rm = self.joint_rotations(j, &self.mid, Some((je, comp, -delta)));
                    self.structure.joint_coefficients(j, &rp, &mut plus);
                    self.structure.joint_coefficients(j, &rm, &mut minus);
                    let wt = self.weight[slots[col_slot]];
                    for r in 0..j.n_rows {
                        let mut dv = 0.0;
                        for (s, &c) in slots.iter().enumerate() {
                            dv += (plus[r * ns + s] - minus[r * ns + s]) * self.mid[c];
                        }
                        self.values[start + r * ns + col_slot] += dv / (2.0 * delta) * wt;
                    }
                }
            }
        }
        let mut p = self.free_nnz;
        for _ in self.structure.free_ends() {
            for _ in 0..k {
                self.values[p] = 1.0;
                p += 1;
            }
        }
        Ok(())
    }

    /// Numeric LU of the assembled step matrix (`values`), reusing the symbolic analysis.
    fn factor(&mut self) -> Result<()> {
        self.factorized = false;
        self.lu
            .factorize(&self.values)
            .map_err(|e| MultibodyError::LinearSolve(format!("sparse LU: {e}")))?;
        self.factorized = true;
        Ok(())
    }

    /// Advances one step of `dt`. Inputs (loads, gravity, torques) are those set now, held
    /// over the step (load amplitudes at the midpoint time).
    pub fn step(&mut self) -> Result<StepReport> {
        self.prepare_loads()?;
        let old = self.state.clone();
        let mut new = match (&self.previous, &self.previous2, self.settings.extrapolate) {
            (Some(p), Some(q), true) => {
                old.iter().zip(p).zip(q).map(|((a, b), c)| 3.0 * a - 3.0 * b + c).collect()
            }
            (Some(p), None, true) => old.iter().zip(p).map(|(a, b)| 2.0 * a - b).collect(),
            _ => old.clone(),
        };
        let mut report = StepReport::default();
        let mut converged = false;
        let mut last_update = f64::INFINITY;
        let mut refresh = !self.factorized || !self.settings.reuse_jacobian;
        let mut fresh = false;
        for it in 0..self.settings.max_newton_iterations {
            self.compute_mid(&old, &new)?;
            self.assemble_residual(&old, &new)?;
            if refresh || it >= self.settings.max_newton_iterations / 2 {
                self.assemble_jacobian(&old, &new)?;
                self.factor()?;
                report.factorizations += 1;
                refresh = !self.settings.reuse_jacobian;
                fresh = true;
            }
            for i in 0..self.residual.len() {
                self.rhs[i] = -self.residual[i];
            }
            if self.lu.solve(&mut self.rhs).is_err() {
                self.factorized = false;
                return Err(MultibodyError::LinearSolve(format!(
                    "non-finite Newton update at t = {} (singular step matrix)",
                    self.time
                )));
            }
            let mut du = 0.0f64;
            let mut xmax = 0.0f64;
            for i in 0..new.len() {
                let d = self.rhs[i];
                new[i] += d;
                du = du.max(d.abs());
                xmax = xmax.max(new[i].abs());
            }
            let rel = du / xmax.max(1.0);
            report.iterations = it + 1;
            report.update = rel;
            let rate = rel / last_update;
            // Converged when the update, or the error left after it (`rate · update` for a
            // contraction), is below the tolerance.
            if rel <= self.settings.newton_tolerance
                || (it >= 1
                    && rate < 0.5
                    && rel * rate / (1.0 - rate) <= self.settings.newton_tolerance)
            {
                converged = true;
                break;
            }
            // Round-off floor: the update no longer shrinks and is already tiny.
            if it >= 2 && rate > 0.5 && rel < self.settings.newton_tolerance.sqrt() * 1e-2 {
                converged = true;
                break;
            }
            // A reused Jacobian that converges slowly (or not at all) is refreshed.
            if it >= 1 && rate > 0.05 && !fresh {
                refresh = true;
            }
            fresh = false;
            last_update = rel;
        }
        if !converged {
            return Err(MultibodyError::NewtonFailed {
                time: self.time,
                residual: report.update,
                iterations: report.iterations,
            });
        }
        // Midpoint diagnostics with the converged state.
        self.compute_mid(&old, &new)?;
        let (vv, bv, jp) = self.midpoint_diagnostics();
        report.velocity_violation = vv;
        report.balance_violation = bv;
        report.joint_power = jp;
        // Kinematics with the midpoint rates.
        for (b, sb) in self.structure.beams().iter().enumerate() {
            let (o, d) = (self.structure.offset(b), sb.beam.dim());
            self.kinematics[b].advance(
                &sb.beam,
                &old[o..o + d],
                &new[o..o + d],
                self.settings.dt,
            )?;
        }
        self.previous2 = self.previous.take();
        self.previous = Some(old);
        self.state = new;
        self.time += self.settings.dt;
        self.steps += 1;
        let prev = self.angles.clone();
        self.angles = self.compute_angles(Some(&prev));
        self.last = report;
        Ok(report)
    }

    /// Max compatibility and balance violations and the joint power at the current `mid`;
    /// stores the end rotations for [`Plant::reactions`].
    fn midpoint_diagnostics(&mut self) -> (f64, f64, f64) {
        let (mut vv, mut bv, mut jp) = (0.0f64, 0.0f64, 0.0);
        let mut all_rot = Vec::with_capacity(self.structure.joints().len());
        for (ji, j) in self.structure.joints().iter().enumerate() {
            let rot = self.joint_rotations(j, &self.mid, None);
            let slots = self.structure.joint_slots(j);
            let ns = slots.len();
            let mut coef = vec![0.0; j.n_rows * ns];
            self.structure.joint_coefficients(j, &rot, &mut coef);
            let mut rhs = vec![0.0; j.n_rows];
            self.structure.joint_rhs(j, &self.torques_of(ji), &mut rhs);
            let kinds: Vec<RowKind> =
                rows(&j.axes, &j.signs, j.ground, &rot).iter().map(|r| r.kind).collect();
            for r in 0..j.n_rows {
                let mut v = -rhs[r];
                for (s, &c) in slots.iter().enumerate() {
                    v += coef[r * ns + s] * self.mid[c];
                }
                match kinds[r] {
                    RowKind::Compatibility => vv = vv.max(v.abs()),
                    RowKind::Balance => bv = bv.max(v.abs()),
                    RowKind::Free => {}
                }
            }
            for (je, &(b, e)) in j.ends.iter().enumerate() {
                let x1 = self.structure.end_velocity(&self.mid, b, e);
                let y = self.structure.end_value(&self.mid, b, e);
                jp += -j.signs[je] * x1.dot(&y);
            }
            all_rot.push(rot);
        }
        self.end_rotations = all_rot;
        (vv, bv, jp)
    }

    fn compute_angles(&self, previous: Option<&[f64]>) -> Vec<f64> {
        let planar = self.structure.k() == 3;
        self.structure
            .joints()
            .iter()
            .enumerate()
            .map(|(ji, j)| {
                let q = |m: usize| {
                    let (b, e) = j.ends[m];
                    self.kinematics[b].xi[self.structure.end_node(b, e)]
                };
                let rel: Vector4<f64> = if j.ground {
                    quat_mul(&quat_conj(&j.reference_relative), &q(0))
                } else {
                    quat_mul(&quat_conj(&q(0)), &q(1))
                };
                // signed angle about the (single) free rotation axis, else the magnitude
                let free = j.free_rotation_axes();
                let raw = if planar || free.len() == 1 {
                    let axis = if planar { Vector3::y() } else { j.axes[free[0]].direction };
                    let s = Vector3::new(rel[1], rel[2], rel[3]).dot(&axis);
                    2.0 * s.atan2(rel[0])
                } else {
                    rotation_angle(&rel)
                };
                match previous {
                    Some(p) if planar || free.len() == 1 => {
                        let two_pi = 2.0 * std::f64::consts::PI;
                        let mut a = raw;
                        while a - p[ji] > std::f64::consts::PI {
                            a -= two_pi;
                        }
                        while a - p[ji] < -std::f64::consts::PI {
                            a += two_pi;
                        }
                        a
                    }
                    _ => raw,
                }
            })
            .collect()
    }

    /// Joint angles (rad), one per joint/support in [`Structure::joints`] order. Planar
    /// structures and joints with one free rotation axis: the signed, unwrapped angle about
    /// that axis (for a two-end joint, of end 1 relative to end 0, reference angle included;
    /// for a support, of the end relative to its reference orientation). Otherwise the
    /// relative rotation angle `2 acos|ξ_rel,0|` in `[0, π]`.
    pub fn joint_angles(&self) -> &[f64] {
        &self.angles
    }

    /// Loads that joint/support `j` applies on each of its ends at the last step's midpoint,
    /// global `[force, moment]`: `−σ_j T_j y_j` (eq. 12); for a support, the ground reaction.
    pub fn reactions(&self, j: usize) -> Vec<Vector6<f64>> {
        let info = &self.structure.joints()[j];
        info.ends
            .iter()
            .enumerate()
            .map(|(je, &(b, e))| {
                end_load_global(
                    &self.end_rotations[j][je],
                    info.signs[je],
                    &self.structure.end_value(&self.state, b, e),
                )
            })
            .collect()
    }

    /// Takes `steps` steps and returns the worst balance, over them, of the loads that
    /// joint/support `j` applies on its ends ([`Plant::reactions`]): a joint in balance (12)
    /// applies forces that sum to zero, and a ball joint applies no moment (paper Fig. 2).
    /// Panics if `j` is not a joint index, as [`Plant::reactions`].
    pub fn run_joint_balance(&mut self, j: usize, steps: usize) -> Result<JointBalance> {
        let mut b = JointBalance::default();
        for _ in 0..steps {
            let r = self.step()?;
            b.velocity_violation = b.velocity_violation.max(r.velocity_violation);
            let loads = self.reactions(j);
            let total: Vector6<f64> = loads.iter().sum();
            b.load_scale = loads.iter().fold(b.load_scale, |s, l| s.max(l.norm()));
            b.force_sum = b.force_sum.max(total.fixed_rows::<3>(0).norm());
            b.moment = loads.iter().fold(b.moment, |m, l| m.max(l.fixed_rows::<3>(3).norm()));
        }
        Ok(b)
    }

    /// Global position of node `n` of beam `b`.
    pub fn position(&self, b: usize, n: usize) -> Vector3<f64> {
        self.kinematics[b].r[n]
    }

    /// Largest distance between joined ends (position gap of the joints).
    pub fn joint_gap(&self) -> f64 {
        let mut g = 0.0f64;
        for j in self.structure.joints().iter().filter(|j| !j.ground) {
            let (b0, e0) = j.ends[0];
            let p0 = self.kinematics[b0].r[self.structure.end_node(b0, e0)];
            for &(b, e) in &j.ends[1..] {
                g = g.max((self.kinematics[b].r[self.structure.end_node(b, e)] - p0).norm());
            }
        }
        g
    }

    /// Linearised step matrix at rest in the reference configuration: rank-deficient iff the
    /// constraints (with the beams' rigid and massless directions) are redundant or
    /// conflicting. On failure, a dense SVD names the joints and beams whose rows are involved.
    fn check_rank(&mut self) -> Result<()> {
        let dim = self.structure.dim();
        let saved = (self.state.clone(), self.mid.clone());
        let zero = vec![0.0; dim];
        let saved_loads =
            std::mem::replace(&mut self.step_loads, vec![Loads::none(); self.loads.len()]);
        self.mid.iter_mut().for_each(|v| *v = 0.0);
        let res = self.assemble_jacobian(&zero, &zero);
        self.step_loads = saved_loads;
        (self.state, self.mid) = saved;
        res?;
        let singular = match self.factor() {
            Err(_) => true,
            Ok(()) => {
                // Solve with a fixed right-hand side and check the size of the solution (a
                // non-finite solution is an error of the solve).
                let mut x: Vec<f64> =
                    (0..dim).map(|i| 1.0 + ((i * 7919) % 13) as f64 / 13.0).collect();
                match self.lu.solve(&mut x) {
                    Err(_) => true,
                    Ok(()) => x.iter().fold(0.0f64, |m, v| m.max(v.abs())) > 1e13,
                }
            }
        };
        // The check's factorisation is not a step Jacobian: the first step factorises afresh.
        self.factorized = false;
        if !singular {
            return Ok(());
        }
        // Dense diagnosis.
        let mut j = Mat::<f64>::zeros(dim, dim);
        let mut pattern = Vec::new();
        for (b, sb) in self.structure.beams().iter().enumerate() {
            sb.beam.jacobian_pattern(
                self.structure.offset(b),
                self.structure.offset(b),
                &mut pattern,
            );
        }
        for ji in 0..self.structure.joints().len() {
            let jinfo = &self.structure.joints()[ji];
            let slots = self.structure.joint_slots(jinfo);
            for r in 0..jinfo.n_rows {
                for &c in &slots {
                    pattern.push((self.row_of_constraint[jinfo.first_row + r], c));
                }
            }
        }
        for &(b, e, r0) in self.structure.free_ends() {
            for a in 0..self.structure.k() {
                pattern
                    .push((self.row_of_constraint[r0 + a], self.structure.x2_end_column(b, e, a)));
            }
        }
        for (p, &(r, c)) in pattern.iter().enumerate() {
            j[(r, c)] += self.values[p];
        }
        let svd = j.svd().map_err(|e| MultibodyError::LinearSolve(format!("SVD: {e:?}")))?;
        let s = svd.S();
        let smax = s[0];
        let rank = (0..dim).filter(|&i| s[i] > 1e-11 * smax).count();
        if rank == dim {
            return Ok(());
        }
        let labels = self.structure.row_labels();
        let mut involved: Vec<String> = Vec::new();
        for col in rank..dim {
            for r in 0..dim {
                if svd.U()[(r, col)].abs() < 1e-6 {
                    continue;
                }
                let name = if let Some(c) = self.row_of_constraint.iter().position(|&x| x == r) {
                    labels[c].owner.clone()
                } else {
                    let b = (0..self.structure.beams().len())
                        .rev()
                        .find(|&b| self.structure.offset(b) <= r)
                        .unwrap_or(0);
                    format!("beam `{}` (rigid/massless directions)", self.structure.beams()[b].name)
                };
                if !involved.contains(&name) {
                    involved.push(name);
                }
            }
        }
        Err(MultibodyError::RedundantConstraints {
            deficiency: dim - rank,
            involved: involved.join(", "),
        })
    }
}
