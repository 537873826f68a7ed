//! The nonlinear modal model (14)–(21) and its augmentation with quaternion modes (22)–(29).
//!
//! State `q_a = [q1 (m), q2 (one per mode that keeps it), qξ (kept quaternion modes)]`:
//!
//! ```text
//!   q̇1 = Σ q1 + Ω q2 − q1_l Γ1^l q1 − q2_l Γ2^l q2 + B_u u + η      (14)–(17)
//!   q̇2 = −Ω q1 + q2_l (Γ2^l)ᵀ q1
//!   q̇ξ = Aξ⁻¹ qξ_l Γξ^l q1                                            (26)–(29)
//! ```
//!
//! with the discrete products of theory.md §2 (node sums for `x1`, element sums for `x2`,
//! `x̄1` at element midpoints): `Γ1^l_ij = Σ_n φ1i(n)ᵀ L1(φ1j(n)) w_n M φ1l(n)` (18),
//! `Γ2^l_ij = Σ_e φ̄1i(e)ᵀ L2(φ2j(e)) h_e C φ2l(e)` (19), `Σ = Φ1ᵀ D_damp Φ1` (16, flux-form
//! `D2` and nodal `D0` of the FE damping operator), `[B_u]_ik = φ1i(node_k)ᵀ e_k` (follower
//! point loads and joint torques, theory.md §5). Quaternion modes (theory.md §6):
//! `φξ0 = ξ̄`, `φξj = Uω(ξ̄) φωj` with the ½ of eq. (8) kept, `Aξ = ⟨φξi, φξj⟩`,
//! `Γξ^l_ij = ⟨φξi, U(φωj) φξl⟩`, node sums with weights `w_n` over all beams; quaternion
//! modes whose field is zero or dependent on the previous ones are dropped so `Aξ` is
//! invertible.

use crate::basis::{ModalBasis, ModeKind};
use crate::blocks::BlockDiag;
use crate::error::{invalid, shape, ModalError, Result};
use crate::layout::Layout;
use crate::tensor::SparseTensor3;
use faer::linalg::solvers::{DenseSolveCore, Solve};
use faer::{Mat, Side};
use intrinsic_beam::operators::{l1_times, l2_times};
use intrinsic_beam::rotation::{u_matrix, u_omega};
use nalgebra::{Vector3, Vector4, Vector6};
use serde::{Deserialize, Serialize};

/// What the reduced model carries (theory.md §5: skip what a scene does not need).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RomOptions {
    /// Keep a `q2` coordinate for rigid modes (`φ2 ≡ 0`, so it stays 0). Default `false`.
    pub rigid_q2: bool,
    /// Carry quaternion states `qξ` (the augmented model 29). Default `true`.
    pub quaternions: bool,
    /// Include the damping matrix `Σ` from the FE damping operator. Default `true`.
    pub damping: bool,
    /// A quaternion mode is kept when its field's part independent of the previously kept ones
    /// has relative norm above this. Default `1e-8`; range `(0, 1e-2]`.
    pub quaternion_tolerance: f64,
    /// `Γ` entries with `|v| ≤ gamma_drop · max|Γ|` are not stored. Default `0` (exact zeros
    /// only, so `qᵀN(q)q = 0` holds to round-off); range `[0, 1e-8]`.
    pub gamma_drop: f64,
}

impl Default for RomOptions {
    fn default() -> Self {
        RomOptions {
            rigid_q2: false,
            quaternions: true,
            damping: true,
            quaternion_tolerance: 1e-8,
            gamma_drop: 0.0,
        }
    }
}

impl RomOptions {
    /// Checks the documented ranges.
    pub fn validate(&self) -> Result<()> {
        if !(self.quaternion_tolerance > 0.0 && self.quaternion_tolerance <= 1e-2) {
            return Err(invalid(
                "quaternion_tolerance",
                self.quaternion_tolerance,
                "must lie in (0, 1e-2]",
            ));
        }
        if !(0.0..=1e-8).contains(&self.gamma_drop) {
            return Err(invalid("gamma_drop", self.gamma_drop, "must lie in [0, 1e-8]"));
        }
        Ok(())
    }
}

/// One input channel: a weighted sum of node velocity components it does work on, i.e. a
/// follower point force/moment (`[B_u]_ik = φ1i(node)ᵀ e`), or a joint torque (opposite
/// moments on the joined ends).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Input {
    /// Name (e.g. `root torque`).
    pub name: String,
    /// `(index in X1, weight)` pairs.
    pub entries: Vec<(usize, f64)>,
}

impl Input {
    /// A follower point load at node `node` of beam `beam`: `load = [f, m]` in the local frame
    /// (spatial components; planar layouts reject out-of-plane components).
    pub fn point(
        layout: &Layout,
        name: &str,
        beam: usize,
        node: usize,
        load: [f64; 6],
    ) -> Result<Input> {
        if beam >= layout.beams.len() {
            return Err(invalid(
                format!("input `{name}`: beam"),
                beam,
                format!("the layout has {} beams", layout.beams.len()),
            ));
        }
        if node >= layout.beams[beam].n_nodes() {
            return Err(invalid(
                format!("input `{name}`: node"),
                node,
                format!("beam {beam} has {} nodes", layout.beams[beam].n_nodes()),
            ));
        }
        let comps = layout.components;
        let mut entries = Vec::new();
        for (s, &v) in load.iter().enumerate() {
            if !v.is_finite() {
                return Err(invalid(format!("input `{name}`: load[{s}]"), v, "must be finite"));
            }
            if v == 0.0 {
                continue;
            }
            match comps.active_index(s) {
                Some(c) => entries.push((layout.x1_index(beam, node, c), v)),
                None => {
                    return Err(invalid(
                        format!("input `{name}`: load[{s}]"),
                        v,
                        "out-of-plane component in a planar layout",
                    ))
                }
            }
        }
        if entries.is_empty() {
            return Err(invalid(
                format!("input `{name}`: load"),
                "0",
                "a load needs a non-zero component",
            ));
        }
        Ok(Input { name: name.to_string(), entries })
    }
}

/// The quaternion part of the augmented model (theory.md §6).
#[derive(Clone, Debug)]
pub struct QuaternionModel {
    /// Kept quaternion modes: `0` is the shifting-equilibrium mode `φξ0 = ξ̄`, `j + 1` is
    /// `Uω(ξ̄)φωj` of velocity mode `j`.
    pub kept: Vec<usize>,
    /// `Aξ` (nξ × nξ), eq. (27).
    pub a_xi: Mat<f64>,
    /// `Aξ⁻¹`.
    pub a_xi_inv: Mat<f64>,
    /// `Γξ^l_ij` (i, l over kept modes, j over velocity modes), eq. (28).
    pub gamma_xi: SparseTensor3,
    /// `(Aξ⁻¹ Γξ^l)_ij`, what the right-hand side uses.
    pub gamma_xi_scaled: SparseTensor3,
    /// Quaternion mode fields at all nodes (4·nodes × nξ; node `n` of all beams in order).
    pub phi_xi: Mat<f64>,
    /// Node weights `w_n` of all beams in order.
    pub weights: Vec<f64>,
}

/// The modal reduced-order model with its projection data.
#[derive(Clone, Debug)]
pub struct ModalRom {
    pub(crate) layout: Layout,
    pub(crate) options: RomOptions,
    pub(crate) kinds: Vec<ModeKind>,
    pub(crate) n_rigid: usize,
    pub(crate) omega: Vec<f64>,
    pub(crate) sigma: Mat<f64>,
    pub(crate) gamma1: SparseTensor3,
    pub(crate) gamma2: SparseTensor3,
    pub(crate) q2_modes: Vec<usize>,
    pub(crate) b_u: Mat<f64>,
    pub(crate) inputs: Vec<String>,
    pub(crate) phi1: Mat<f64>,
    pub(crate) phi2: Mat<f64>,
    pub(crate) proj1: Mat<f64>,
    pub(crate) proj2: Mat<f64>,
    pub(crate) compliance: Vec<Vec<f64>>,
    pub(crate) quaternion: Option<QuaternionModel>,
}

fn mat_from_rows(rows: usize, cols: usize, f: impl Fn(usize, usize) -> f64) -> Mat<f64> {
    Mat::from_fn(rows, cols, f)
}

impl ModalRom {
    /// Builds the model from (a selection of) modes. `damping` is the FE damping operator on
    /// `X1` (n1 × n1) when the scene has one; `inputs` define the columns of `B_u`.
    pub fn new(
        basis: &ModalBasis,
        damping: Option<&Mat<f64>>,
        inputs: &[Input],
        options: &RomOptions,
    ) -> Result<Self> {
        options.validate()?;
        let layout = basis.layout().clone();
        let comps = layout.components;
        let k = comps.k();
        let (n1, n2) = (layout.n1(), layout.n2());
        let m = basis.n_modes();
        if m == 0 {
            return Err(invalid("basis", 0, "a reduced model needs at least one mode"));
        }
        let phi1 = basis.phi1().to_owned();
        let phi2 = basis.phi2().to_owned();
        let n_rigid = basis.n_rigid();
        let q2_modes: Vec<usize> = (0..m).filter(|&j| options.rigid_q2 || j >= n_rigid).collect();
        // Σ (16)
        let sigma = match (damping, options.damping) {
            (Some(d), true) => {
                if d.nrows() != n1 || d.ncols() != n1 {
                    return Err(shape("damping operator", (n1, n1), (d.nrows(), d.ncols())));
                }
                let mut s = phi1.transpose() * d * &phi1;
                for j in 0..m {
                    for i in 0..j {
                        let a = 0.5 * (s[(i, j)] + s[(j, i)]);
                        s[(i, j)] = a;
                        s[(j, i)] = a;
                    }
                }
                s
            }
            _ => Mat::zeros(m, m),
        };
        // Embedded mode values and their weighted products.
        let b1phi = basis.b1_blocks().apply(phi1.as_ref()); // w_n M φ1l at nodes
        let b2phi = basis.b2_blocks().apply(phi2.as_ref()); // h_e C φ2l at elements
        let emb = |mat: &Mat<f64>, i0: usize, j: usize| -> Vector6<f64> {
            let vals: Vec<f64> = (0..k).map(|c| mat[(i0 + c, j)]).collect();
            comps.embed(&vals)
        };
        let mut g1 = vec![0.0; m * m * m];
        let mut g2 = vec![0.0; m * q2_modes.len() * q2_modes.len()];
        let nq2 = q2_modes.len();
        for (b, beam) in layout.beams.iter().enumerate() {
            for n in 0..beam.n_nodes() {
                let i0 = layout.x1_index(b, n, 0);
                let p: Vec<Vector6<f64>> = (0..m).map(|j| emb(&phi1, i0, j)).collect();
                if p.iter().all(|v| v.iter().all(|x| *x == 0.0)) {
                    continue;
                }
                let mp: Vec<Vector6<f64>> = (0..m).map(|j| emb(&b1phi, i0, j)).collect();
                for l in 0..m {
                    for j in 0..m {
                        let t = l1_times(&p[j], &mp[l]);
                        if t.iter().all(|x| *x == 0.0) {
                            continue;
                        }
                        for i in 0..m {
                            g1[(l * m + i) * m + j] += p[i].dot(&t);
                        }
                    }
                }
            }
            for e in 0..beam.n_elements() {
                let i0 = layout.x2_index(b, e, 0);
                let (na, nb) = (layout.x1_index(b, e, 0), layout.x1_index(b, e + 1, 0));
                let bar: Vec<Vector6<f64>> =
                    (0..m).map(|j| (emb(&phi1, na, j) + emb(&phi1, nb, j)) * 0.5).collect();
                let p2: Vec<Vector6<f64>> = q2_modes.iter().map(|&j| emb(&phi2, i0, j)).collect();
                let cp2: Vec<Vector6<f64>> = q2_modes.iter().map(|&j| emb(&b2phi, i0, j)).collect();
                for l in 0..nq2 {
                    for j in 0..nq2 {
                        let t = l2_times(&p2[j], &cp2[l]);
                        if t.iter().all(|x| *x == 0.0) {
                            continue;
                        }
                        for i in 0..m {
                            g2[(l * m + i) * nq2 + j] += bar[i].dot(&t);
                        }
                    }
                }
            }
        }
        let drop1 = options.gamma_drop * g1.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let drop2 = options.gamma_drop * g2.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let gamma1 = SparseTensor3::from_dense((m, m, m), &g1, drop1);
        let gamma2 = SparseTensor3::from_dense((m, nq2, nq2), &g2, drop2);
        // B_u
        let mut b_u = Mat::<f64>::zeros(m, inputs.len());
        for (c, input) in inputs.iter().enumerate() {
            for &(idx, w) in &input.entries {
                if idx >= n1 {
                    return Err(invalid(
                        format!("input `{}` index", input.name),
                        idx,
                        format!("X1 has {n1} entries"),
                    ));
                }
                for i in 0..m {
                    b_u[(i, c)] += phi1[(idx, i)] * w;
                }
            }
        }
        // Projections: energy-norm least squares onto the modes (theory.md §7).
        let proj1 = gram_projector(&phi1, basis.b1_blocks())?;
        let phi2q = mat_from_rows(n2, nq2, |i, p| phi2[(i, q2_modes[p])]);
        let proj2 = if q2_modes.iter().any(|&j| j < n_rigid) {
            // rigid modes have φ2 ≡ 0: their q2 is 0; project on the elastic ones only
            let el: Vec<usize> = (0..nq2).filter(|&p| q2_modes[p] >= n_rigid).collect();
            let sub = mat_from_rows(n2, el.len(), |i, p| phi2q[(i, el[p])]);
            let ps = gram_projector(&sub, basis.b2_blocks())?;
            let mut full = Mat::<f64>::zeros(nq2, n2);
            for (r, &p) in el.iter().enumerate() {
                for c in 0..n2 {
                    full[(p, c)] = ps[(r, c)];
                }
            }
            full
        } else {
            gram_projector(&phi2q, basis.b2_blocks())?
        };
        let compliance = (0..layout.beams.len())
            .map(|b| {
                let h = layout.beams[b].element_lengths[0];
                let i0 = layout.x2_index(b, 0, 0);
                basis.b2_blocks().block(i0 / k).iter().map(|v| v / h).collect()
            })
            .collect();
        let quaternion = if options.quaternions {
            Some(quaternion_model(&layout, &phi1, options.quaternion_tolerance)?)
        } else {
            None
        };
        Ok(ModalRom {
            layout,
            options: options.clone(),
            kinds: basis.kinds().to_vec(),
            n_rigid,
            omega: basis.omega().to_vec(),
            sigma,
            gamma1,
            gamma2,
            q2_modes,
            b_u,
            inputs: inputs.iter().map(|i| i.name.clone()).collect(),
            phi1,
            phi2,
            proj1,
            proj2,
            compliance,
            quaternion,
        })
    }

    /// Number of velocity modes `m` (= length of `q1`).
    pub fn n_modes(&self) -> usize {
        self.omega.len()
    }

    /// Number of rigid modes (the first ones).
    pub fn n_rigid(&self) -> usize {
        self.n_rigid
    }

    /// Number of `q2` coordinates.
    pub fn n_q2(&self) -> usize {
        self.q2_modes.len()
    }

    /// Number of quaternion coordinates `qξ` (0 without quaternions).
    pub fn n_xi(&self) -> usize {
        self.quaternion.as_ref().map_or(0, |q| q.kept.len())
    }

    /// State length `m + n_q2 + n_xi`.
    pub fn n_state(&self) -> usize {
        self.n_modes() + self.n_q2() + self.n_xi()
    }

    /// Offset of `q2` in the state.
    pub fn q2_offset(&self) -> usize {
        self.n_modes()
    }

    /// Offset of `qξ` in the state.
    pub fn xi_offset(&self) -> usize {
        self.n_modes() + self.n_q2()
    }

    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        self.b_u.ncols()
    }

    /// Input names.
    pub fn input_names(&self) -> &[String] {
        &self.inputs
    }

    /// Frequencies `Ω`.
    pub fn omega(&self) -> &[f64] {
        &self.omega
    }

    /// Kinds of the velocity modes.
    pub fn kinds(&self) -> &[ModeKind] {
        &self.kinds
    }

    /// The mode index of each `q2` coordinate.
    pub fn q2_modes(&self) -> &[usize] {
        &self.q2_modes
    }

    /// Damping matrix `Σ` (m × m, symmetric negative semidefinite).
    pub fn sigma(&self) -> &Mat<f64> {
        &self.sigma
    }

    /// `Γ1` (18), sparse.
    pub fn gamma1(&self) -> &SparseTensor3 {
        &self.gamma1
    }

    /// `Γ2` (19), sparse; `j, l` index the `q2` coordinates.
    pub fn gamma2(&self) -> &SparseTensor3 {
        &self.gamma2
    }

    /// Input matrix `B_u` (m × inputs).
    pub fn b_u(&self) -> &Mat<f64> {
        &self.b_u
    }

    /// The quaternion part, when carried.
    pub fn quaternion(&self) -> Option<&QuaternionModel> {
        self.quaternion.as_ref()
    }

    /// Options the model was built with.
    pub fn options(&self) -> &RomOptions {
        &self.options
    }

    /// Layout of the structure.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The reference state: zero velocities and forces, `qξ = e0` (the undeformed field
    /// projects to exactly `qξ0 = 1` with `φξ0 = ξ̄` unnormalised, theory.md §6).
    pub fn reference_state(&self) -> Vec<f64> {
        let mut q = vec![0.0; self.n_state()];
        if self.n_xi() > 0 {
            q[self.xi_offset()] = 1.0;
        }
        q
    }

    /// `η` of a uniform distributed follower load `[f, m]` (local, per unit length) on beam
    /// `beam`: `η_i = Σ_n w_n φ1i(n)ᵀ f1` (20).
    pub fn distributed_load(&self, beam: usize, load: [f64; 6]) -> Result<Vec<f64>> {
        if beam >= self.layout.beams.len() {
            return Err(invalid(
                "distributed load beam",
                beam,
                format!("the layout has {} beams", self.layout.beams.len()),
            ));
        }
        let comps = self.layout.components;
        let b = &self.layout.beams[beam];
        let mut eta = vec![0.0; self.n_modes()];
        for n in 0..b.n_nodes() {
            let w = b.node_weight(n);
            for c in 0..comps.k() {
                let f = load[comps.spatial_index(c)];
                if f == 0.0 {
                    continue;
                }
                let idx = self.layout.x1_index(beam, n, c);
                for (i, e) in eta.iter_mut().enumerate() {
                    *e += w * f * self.phi1[(idx, i)];
                }
            }
        }
        Ok(eta)
    }

    fn check(&self, q: &[f64], u: &[f64]) -> Result<()> {
        if q.len() != self.n_state() {
            return Err(shape("state q", (self.n_state(), 1), (q.len(), 1)));
        }
        if u.len() != self.n_inputs() {
            return Err(shape("input u", (self.n_inputs(), 1), (u.len(), 1)));
        }
        if let Some(i) = q.iter().position(|v| !v.is_finite()) {
            return Err(ModalError::NonFinite { what: "state q".into(), index: i });
        }
        if let Some(i) = u.iter().position(|v| !v.is_finite()) {
            return Err(ModalError::NonFinite { what: "input u".into(), index: i });
        }
        Ok(())
    }

    /// Right-hand side `q̇ = f(q, u)` (29) into `out`.
    pub fn rhs(&self, q: &[f64], u: &[f64], out: &mut [f64]) -> Result<()> {
        self.check(q, u)?;
        if out.len() != self.n_state() {
            return Err(shape("output", (self.n_state(), 1), (out.len(), 1)));
        }
        self.rhs_unchecked(q, u, out);
        Ok(())
    }

    fn rhs_unchecked(&self, q: &[f64], u: &[f64], out: &mut [f64]) {
        let m = self.n_modes();
        let o2 = self.q2_offset();
        let ox = self.xi_offset();
        let (q1, q2) = (&q[..m], &q[o2..ox]);
        out.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..m {
            let mut acc = 0.0;
            for j in 0..m {
                acc += self.sigma[(i, j)] * q1[j];
            }
            for c in 0..u.len() {
                acc += self.b_u[(i, c)] * u[c];
            }
            out[i] = acc;
        }
        for (p, &j) in self.q2_modes.iter().enumerate() {
            out[j] += self.omega[j] * q2[p];
            out[o2 + p] = -self.omega[j] * q1[j];
        }
        for &(i, j, l, v) in &self.gamma1.entries {
            out[i as usize] -= v * q1[j as usize] * q1[l as usize];
        }
        for &(i, j, l, v) in &self.gamma2.entries {
            let (i, j, l) = (i as usize, j as usize, l as usize);
            out[i] -= v * q2[j] * q2[l];
            out[o2 + j] += v * q1[i] * q2[l];
        }
        if let Some(qm) = &self.quaternion {
            let qx = &q[ox..];
            for &(i, j, l, v) in &qm.gamma_xi_scaled.entries {
                out[ox + i as usize] += v * q1[j as usize] * qx[l as usize];
            }
        }
    }

    /// Exact Jacobians `∂f/∂q` (n × n) and `∂f/∂u` (n × inputs), written column-major into
    /// `jq` (length n²) and `ju` (length n·inputs) — the layout of `nalgebra::DMatrix` and of
    /// faer's column-major `Mat`. The right-hand side is quadratic in `q`, so `∂f/∂q` is
    /// affine in `q`.
    pub fn jacobian(&self, q: &[f64], u: &[f64], jq: &mut [f64], ju: &mut [f64]) -> Result<()> {
        self.check(q, u)?;
        let n = self.n_state();
        if jq.len() != n * n {
            return Err(shape("Jacobian ∂f/∂q", (n, n), (jq.len(), 1)));
        }
        if ju.len() != n * self.n_inputs() {
            return Err(shape("Jacobian ∂f/∂u", (n, self.n_inputs()), (ju.len(), 1)));
        }
        let m = self.n_modes();
        let o2 = self.q2_offset();
        let ox = self.xi_offset();
        let (q1, q2) = (&q[..m], &q[o2..ox]);
        jq.fill(0.0);
        ju.fill(0.0);
        for j in 0..m {
            for i in 0..m {
                jq[j * n + i] = self.sigma[(i, j)];
            }
        }
        for c in 0..self.n_inputs() {
            for i in 0..m {
                ju[c * n + i] = self.b_u[(i, c)];
            }
        }
        for (p, &j) in self.q2_modes.iter().enumerate() {
            jq[(o2 + p) * n + j] += self.omega[j];
            jq[j * n + o2 + p] -= self.omega[j];
        }
        for &(i, j, l, v) in &self.gamma1.entries {
            let (i, j, l) = (i as usize, j as usize, l as usize);
            jq[j * n + i] -= v * q1[l];
            jq[l * n + i] -= v * q1[j];
        }
        for &(i, j, l, v) in &self.gamma2.entries {
            let (i, j, l) = (i as usize, j as usize, l as usize);
            jq[(o2 + j) * n + i] -= v * q2[l];
            jq[(o2 + l) * n + i] -= v * q2[j];
            jq[i * n + o2 + j] += v * q2[l];
            jq[(o2 + l) * n + o2 + j] += v * q1[i];
        }
        if let Some(qm) = &self.quaternion {
            let qx = &q[ox..];
            for &(i, j, l, v) in &qm.gamma_xi_scaled.entries {
                let (i, j, l) = (i as usize, j as usize, l as usize);
                jq[j * n + ox + i] += v * qx[l];
                jq[(ox + l) * n + ox + i] += v * q1[j];
            }
        }
        Ok(())
    }

    /// Right-hand side and both Jacobians in one pass over the tensors (what an integrator
    /// with sensitivities needs); layouts as in [`ModalRom::rhs`] and [`ModalRom::jacobian`].
    pub fn rhs_and_jacobian(
        &self,
        q: &[f64],
        u: &[f64],
        f: &mut [f64],
        jq: &mut [f64],
        ju: &mut [f64],
    ) -> Result<()> {
        self.check(q, u)?;
        let n = self.n_state();
        let nu = self.n_inputs();
        if f.len() != n {
            return Err(shape("output", (n, 1), (f.len(), 1)));
        }
        if jq.len() != n * n {
            return Err(shape("Jacobian ∂f/∂q", (n, n), (jq.len(), 1)));
        }
        if ju.len() != n * nu {
            return Err(shape("Jacobian ∂f/∂u", (n, nu), (ju.len(), 1)));
        }
        let m = self.n_modes();
        let o2 = self.q2_offset();
        let ox = self.xi_offset();
        let (q1, q2, qx) = (&q[..m], &q[o2..ox], &q[ox..]);
        jq.fill(0.0);
        f.fill(0.0);
        for j in 0..m {
            let col = self.sigma.col_as_slice(j);
            let jcol = &mut jq[j * n..j * n + m];
            let qj = q1[j];
            jcol.copy_from_slice(&col[..m]);
            for i in 0..m {
                f[i] += col[i] * qj;
            }
        }
        for c in 0..nu {
            let col = self.b_u.col_as_slice(c);
            let jcol = &mut ju[c * n..(c + 1) * n];
            jcol.fill(0.0);
            let uc = u[c];
            jcol[..m].copy_from_slice(&col[..m]);
            for i in 0..m {
                f[i] += col[i] * uc;
            }
        }
        for (p, &j) in self.q2_modes.iter().enumerate() {
            let w = self.omega[j];
            f[j] += w * q2[p];
            f[o2 + p] = -w * q1[j];
            jq[(o2 + p) * n + j] += w;
            jq[j * n + o2 + p] -= w;
        }
        for &(i, j, l, v) in &self.gamma1.entries {
            let (i, j, l) = (i as usize, j as usize, l as usize);
            let (a, b) = (v * q1[l], v * q1[j]);
            f[i] -= a * q1[j];
            jq[j * n + i] -= a;
            jq[l * n + i] -= b;
        }
        for &(i, j, l, v) in &self.gamma2.entries {
            let (i, j, l) = (i as usize, j as usize, l as usize);
            let (a, b) = (v * q2[l], v * q2[j]);
            f[i] -= a * q2[j];
            f[o2 + j] += a * q1[i];
            jq[(o2 + j) * n + i] -= a;
            jq[(o2 + l) * n + i] -= b;
            jq[i * n + o2 + j] += a;
            jq[(o2 + l) * n + o2 + j] += v * q1[i];
        }
        if let Some(qm) = &self.quaternion {
            for &(i, j, l, v) in &qm.gamma_xi_scaled.entries {
                let (i, j, l) = (i as usize, j as usize, l as usize);
                let a = v * qx[l];
                f[ox + i] += a * q1[j];
                jq[j * n + ox + i] += a;
                jq[(ox + l) * n + ox + i] += v * q1[j];
            }
        }
        Ok(())
    }

    /// `out = Σ_i w_i ∇²f_i` (symmetric, `(n + inputs)²`, column-major, ordered `(q, u)`):
    /// constant, since `f` is quadratic in `q` and linear in `u`.
    pub fn weighted_hessian(&self, w: &[f64], out: &mut [f64]) -> Result<()> {
        let n = self.n_state();
        let nt = n + self.n_inputs();
        if w.len() != n {
            return Err(shape("weights w", (n, 1), (w.len(), 1)));
        }
        if out.len() != nt * nt {
            return Err(shape("Hessian", (nt, nt), (out.len(), 1)));
        }
        out.fill(0.0);
        let (o2, ox) = (self.q2_offset(), self.xi_offset());
        let mut add = |a: usize, b: usize, v: f64| {
            out[b * nt + a] += v;
            out[a * nt + b] += v;
        };
        for &(i, j, l, v) in &self.gamma1.entries {
            add(j as usize, l as usize, -v * w[i as usize]);
        }
        for &(i, j, l, v) in &self.gamma2.entries {
            let (i, j, l) = (i as usize, j as usize, l as usize);
            add(o2 + j, o2 + l, -v * w[i]);
            add(i, o2 + l, v * w[o2 + j]);
        }
        if let Some(qm) = &self.quaternion {
            for &(i, j, l, v) in &qm.gamma_xi_scaled.entries {
                add(j as usize, ox + l as usize, v * w[ox + i as usize]);
            }
        }
        Ok(())
    }

    /// `qᵀ N(q) q` of the `(q1, q2)` part (zero by the energy identity, theory.md §5).
    pub fn energy_neutrality(&self, q: &[f64]) -> Result<f64> {
        let u = vec![0.0; self.n_inputs()];
        self.check(q, &u)?;
        let m = self.n_modes();
        let o2 = self.q2_offset();
        let ox = self.xi_offset();
        let (q1, q2) = (&q[..m], &q[o2..ox]);
        let mut s = 0.0;
        for &(i, j, l, v) in &self.gamma1.entries {
            s -= q1[i as usize] * v * q1[j as usize] * q1[l as usize];
        }
        for &(i, j, l, v) in &self.gamma2.entries {
            let (i, j, l) = (i as usize, j as usize, l as usize);
            s -= q1[i] * v * q2[j] * q2[l];
            s += q2[j] * v * q1[i] * q2[l];
        }
        Ok(s)
    }

    /// Energy `½ (q1ᵀq1 + q2ᵀq2)` (21).
    pub fn energy(&self, q: &[f64]) -> f64 {
        0.5 * q[..self.xi_offset()].iter().map(|v| v * v).sum::<f64>()
    }

    /// One implicit-midpoint step `q⁺ = q + dt f((q + q⁺)/2, u)` by Newton on the exact
    /// Jacobian (faer LU), to `‖Δ‖∞ ≤ tol · max(1, ‖q‖∞)`. Returns the Newton iterations.
    pub fn midpoint_step(
        &self,
        q: &mut [f64],
        u: &[f64],
        dt: f64,
        tol: f64,
        max_iter: usize,
    ) -> Result<usize> {
        self.check(q, u)?;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid("dt", dt, "must be finite and > 0"));
        }
        let n = self.n_state();
        let q0 = q.to_vec();
        let mut z = q0.clone();
        let mut f = vec![0.0; n];
        let mut mid = vec![0.0; n];
        let mut jq = vec![0.0; n * n];
        let mut ju = vec![0.0; n * self.n_inputs()];
        let scale = q0.iter().fold(1.0f64, |a, v| a.max(v.abs()));
        for it in 1..=max_iter {
            for i in 0..n {
                mid[i] = 0.5 * (q0[i] + z[i]);
            }
            self.rhs_unchecked(&mid, u, &mut f);
            self.jacobian(&mid, u, &mut jq, &mut ju)?;
            let mut a = Mat::<f64>::from_fn(n, n, |i, j| -0.5 * dt * jq[j * n + i]);
            for i in 0..n {
                a[(i, i)] += 1.0;
            }
            let mut r = Mat::<f64>::from_fn(n, 1, |i, _| -(z[i] - q0[i] - dt * f[i]));
            a.partial_piv_lu().solve_in_place(r.as_mut());
            let mut step = 0.0f64;
            for i in 0..n {
                z[i] += r[(i, 0)];
                step = step.max(r[(i, 0)].abs());
            }
            if !step.is_finite() {
                return Err(ModalError::Numerical {
                    stage: "implicit midpoint Newton".into(),
                    reason: "non-finite update".into(),
                });
            }
            if step <= tol * scale {
                q.copy_from_slice(&z);
                return Ok(it);
            }
        }
        Err(ModalError::Numerical {
            stage: "implicit midpoint Newton".into(),
            reason: format!("no convergence in {max_iter} iterations"),
        })
    }

    /// One classical RK4 step with `u` held constant.
    pub fn rk4_step(&self, q: &mut [f64], u: &[f64], dt: f64) -> Result<()> {
        self.check(q, u)?;
        let n = self.n_state();
        let mut k = vec![vec![0.0; n]; 4];
        let mut tmp = vec![0.0; n];
        self.rhs_unchecked(q, u, &mut k[0]);
        for s in 1..4 {
            let c = if s == 3 { 1.0 } else { 0.5 };
            for i in 0..n {
                tmp[i] = q[i] + c * dt * k[s - 1][i];
            }
            let (_, rest) = k.split_at_mut(s);
            self.rhs_unchecked(&tmp, u, &mut rest[0]);
        }
        for i in 0..n {
            q[i] += dt / 6.0 * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i]);
        }
        if let Some(i) = q.iter().position(|v| !v.is_finite()) {
            return Err(ModalError::NonFinite { what: "RK4 state".into(), index: i });
        }
        Ok(())
    }
}

/// `(ΦᵀBΦ)⁻¹ ΦᵀB`: the energy-norm projector onto the columns of `Φ`.
fn gram_projector(phi: &Mat<f64>, b: &BlockDiag) -> Result<Mat<f64>> {
    let bphi = b.apply(phi.as_ref());
    let gram = phi.transpose() * &bphi;
    if gram.nrows() == 0 {
        return Ok(Mat::zeros(0, phi.nrows()));
    }
    let llt = gram.llt(Side::Lower).map_err(|e| ModalError::Numerical {
        stage: "Gram matrix of the modes".into(),
        reason: format!("{e:?}"),
    })?;
    Ok(llt.solve(bphi.transpose().to_owned()))
}

fn quaternion_model(layout: &Layout, phi1: &Mat<f64>, tol: f64) -> Result<QuaternionModel> {
    let comps = layout.components;
    let k = comps.k();
    let m = phi1.ncols();
    let nodes = layout.n_nodes_total();
    let mut weights = Vec::with_capacity(nodes);
    let mut xibar = Vec::with_capacity(nodes);
    let mut omegas: Vec<Vec<Vector3<f64>>> = Vec::with_capacity(nodes); // per node, per mode
    for (b, beam) in layout.beams.iter().enumerate() {
        for n in 0..beam.n_nodes() {
            weights.push(beam.node_weight(n));
            xibar.push(beam.xi(n));
            let i0 = layout.x1_index(b, n, 0);
            omegas.push(
                (0..m)
                    .map(|j| {
                        let vals: Vec<f64> = (0..k).map(|c| phi1[(i0 + c, j)]).collect();
                        let e = comps.embed(&vals);
                        Vector3::new(e[3], e[4], e[5])
                    })
                    .collect(),
            );
        }
    }
    // candidate fields: 0 = ξ̄, j + 1 = Uω(ξ̄) φωj
    let field = |c: usize, n: usize| -> Vector4<f64> {
        if c == 0 {
            xibar[n]
        } else {
            u_omega(&xibar[n]) * omegas[n][c - 1]
        }
    };
    let dot = |a: &[Vector4<f64>], b: &[Vector4<f64>]| -> f64 {
        (0..nodes).map(|n| weights[n] * a[n].dot(&b[n])).sum()
    };
    let mut kept = Vec::new();
    let mut fields: Vec<Vec<Vector4<f64>>> = Vec::new();
    let mut ortho: Vec<Vec<Vector4<f64>>> = Vec::new();
    let ref_norm = dot(
        &(0..nodes).map(|n| xibar[n]).collect::<Vec<_>>(),
        &(0..nodes).map(|n| xibar[n]).collect::<Vec<_>>(),
    )
    .sqrt();
    for c in 0..=m {
        let f: Vec<Vector4<f64>> = (0..nodes).map(|n| field(c, n)).collect();
        let norm0 = dot(&f, &f).sqrt();
        if norm0 <= 1e-12 * ref_norm {
            continue;
        }
        let mut r = f.clone();
        for _ in 0..2 {
            for o in &ortho {
                let a = dot(&r, o);
                for n in 0..nodes {
                    r[n] -= o[n] * a;
                }
            }
        }
        let nr = dot(&r, &r).sqrt();
        if nr > tol * norm0 {
            kept.push(c);
            ortho.push(r.iter().map(|v| v / nr).collect());
            fields.push(f);
        }
    }
    let nx = kept.len();
    let a_xi = Mat::from_fn(nx, nx, |i, j| dot(&fields[i], &fields[j]));
    let llt = a_xi.llt(Side::Lower).map_err(|e| ModalError::Numerical {
        stage: "Cholesky of Aξ".into(),
        reason: format!("{e:?}"),
    })?;
    let a_xi_inv = llt.inverse();
    let mut dense = vec![0.0; nx * m * nx];
    for n in 0..nodes {
        for j in 0..m {
            let w = omegas[n][j];
            if w == Vector3::zeros() {
                continue;
            }
            let u = u_matrix(&w);
            for l in 0..nx {
                let t = u * fields[l][n];
                for i in 0..nx {
                    dense[(l * nx + i) * m + j] += weights[n] * fields[i][n].dot(&t);
                }
            }
        }
    }
    let gamma_xi = SparseTensor3::from_dense((nx, m, nx), &dense, 0.0);
    let gamma_xi_scaled = scale_gamma_xi(&a_xi_inv, &dense, nx, m);
    let phi_xi = Mat::from_fn(4 * nodes, nx, |r, c| fields[c][r / 4][r % 4]);
    Ok(QuaternionModel { kept, a_xi, a_xi_inv, gamma_xi, gamma_xi_scaled, phi_xi, weights })
}

/// `Aξ⁻¹ Γξ^l` from the dense `Γξ` indexed `[(l·nx + i)·m + j]`.
pub(crate) fn scale_gamma_xi(
    a_xi_inv: &Mat<f64>,
    dense: &[f64],
    nx: usize,
    m: usize,
) -> SparseTensor3 {
    let mut scaled = vec![0.0; nx * m * nx];
    for l in 0..nx {
        for i in 0..nx {
            for j in 0..m {
                let mut acc = 0.0;
                for p in 0..nx {
                    acc += a_xi_inv[(i, p)] * dense[(l * nx + p) * m + j];
                }
                scaled[(l * nx + i) * m + j] = acc;
            }
        }
    }
    SparseTensor3::from_dense((nx, m, nx), &scaled, 0.0)
}
