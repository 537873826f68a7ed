//! The exact-joints reduced model: state, right-hand side, exact Jacobian, implicit
//! midpoint (theory.md §10).
//!
//! State `x = [p (m), p2 (m2), ξ_root (4, when the structure has a support), ξ_j (4 per joint)]`
//! with link-field coordinates `q1 = Z(ξ) p`, `q2 = Z2 p2`:
//!
//! ```text
//!   ṗ    = Zᵀ f1(Zp, Z2p2, u) − K(Ȧ) p,        Ȧ = Σ_j Σ_c ∂A/∂ξ_jc · ξ̇_jc
//!   ṗ2   = Z2ᵀ f2(Zp, Z2p2)
//!   ξ̇_root = U(ω_root) ξ_root                     (eq. 7, body rate at the supported node)
//!   ξ̇_j  = U(ω_b) ξ_j − Ū(ω_a) ξ_j               (ξ_j = ξ_a* ⊗ ξ_b, the joint's relative rotation)
//! ```
//!
//! with `U(ω) = ½[[0, −ωᵀ], [ω, −ω̃]]` (8), `Ū(ω) = ½[[0, −ωᵀ], [ω, ω̃]]` and the rates `ω` the
//! model's own, `ω = (rows of Φ1 at the node) q1`. `ZᵀZ = I`, `K = ZᵀŻ` is skew and
//! `q1ᵀf1 + q2ᵀf2` holds no work but damping and input, so `½|p|² + ½|p2|²` is exactly the
//! energy and is conserved without damping and input.

use crate::error::{invalid, shape, ModalError, Result};
use crate::exact_joints::ambient::{AmbientOps, LinkBasis};
use crate::exact_joints::eval::with_workspace;
use crate::exact_joints::planar::Planar;
use crate::exact_joints::rows::{relative_quaternion, Constraints};
use crate::rom::Input;
use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};
use intrinsic_beam::Kinematics;
use multibody_constraints::Structure;
use nalgebra::{Matrix4, Vector3, Vector4};

/// The parts of a model its export writes: Galerkin operators, rows, `Z0`, `Z2` and the
/// `(component, rate axis)` of the rotational components.
pub(crate) type ModelParts<'a> =
    (&'a AmbientOps, &'a Constraints, &'a Mat<f64>, &'a Mat<f64>, &'a [(usize, usize)]);

/// `U(ω)` of eq. (8): `U(ω)ξ = ½ ξ ⊗ (0, ω)`.
pub(super) fn u_right(w: &Vector3<f64>) -> Matrix4<f64> {
    Matrix4::new(
        0.0, -w.x, -w.y, -w.z, //
        w.x, 0.0, w.z, -w.y, //
        w.y, -w.z, 0.0, w.x, //
        w.z, w.y, -w.x, 0.0,
    ) * 0.5
}

/// `Ū(ω)`: `Ū(ω)ξ = ½ (0, ω) ⊗ ξ`.
pub(super) fn u_left(w: &Vector3<f64>) -> Matrix4<f64> {
    Matrix4::new(
        0.0, -w.x, -w.y, -w.z, //
        w.x, 0.0, -w.z, w.y, //
        w.y, w.z, 0.0, -w.x, //
        w.z, -w.y, w.x, 0.0,
    ) * 0.5
}

fn flat(m: &Mat<f64>) -> Vec<f64> {
    (0..m.ncols()).flat_map(|j| (0..m.nrows()).map(move |i| m[(i, j)])).collect()
}

fn col(m: &Mat<f64>, j: usize) -> Vec<f64> {
    (0..m.nrows()).map(|i| m[(i, j)]).collect()
}

/// Rows `T` on the link fields whose products with `Z(ξ)` the evaluation needs (a joint's
/// end-node values `E_j`, or the root node's values), with their constant products.
#[derive(Clone, Debug)]
pub(super) struct Tracked {
    /// `T` (`t × na`) and its column-major copy.
    pub rows: Mat<f64>,
    pub rows_flat: Vec<f64>,
    /// `T Z0` (`t × m`).
    pub z0: Vec<f64>,
    /// `T Sᵀ` (`t × rs`), support rows `S`.
    pub s: Vec<f64>,
    /// `T E_iᵀ` (`t × 2k`) per joint `i`.
    pub e: Vec<Vec<f64>>,
}

/// The exact-joints reduced model (module docs; theory.md §10).
#[derive(Clone, Debug)]
pub struct ExactJointsRom {
    pub(super) basis: LinkBasis,
    pub(super) ops: AmbientOps,
    pub(super) cons: Constraints,
    pub(super) z0: Mat<f64>,
    pub(super) z2: Mat<f64>,
    pub(super) z2_identity: bool,
    inputs: Vec<String>,
    /// Per joint, then the root node (when carried).
    pub(super) tracked: Vec<Tracked>,
    /// `S Sᵀ` (`rs × rs`).
    pub(super) ss: Vec<f64>,
    flat: FlatCopies,
    /// `(component, rate axis)` of the rotational components.
    pub(super) rate_comps: Vec<(usize, usize)>,
    /// First row of each joint in `A`.
    pub(super) row_offsets: Vec<usize>,
    /// The planar evaluation's constants when the model is planar.
    pub(super) planar: Option<Box<Planar>>,
}

/// Column-major copies of the constant matrices.
#[derive(Clone, Debug, Default)]
struct FlatCopies {
    support: Vec<f64>,
    e: Vec<Vec<f64>>,
    /// `Sᵀ` (`na × rs`) and `E_jᵀ` (`na × 2k`), column-major (left factors of products).
    support_t: Vec<f64>,
    e_t: Vec<Vec<f64>>,
    z0: Vec<f64>,
    z2: Vec<f64>,
}

impl ExactJointsRom {
    /// The model on link fields `basis` with all motions compatible at the reference joint
    /// rotations: `Z0` an orthonormal basis of `null A(ξ̄)` (Gram–Schmidt of `P(ξ̄) e_i` in
    /// order, deterministic), `Z2 = I`.
    pub fn new(
        structure: &Structure,
        basis: LinkBasis,
        damping: Option<&Mat<f64>>,
        inputs: &[Input],
    ) -> Result<Self> {
        let nb = basis.n2();
        let na = basis.n1();
        let cons = Constraints::new(structure, &basis)?;
        let a0 = cons.rows_at_reference(na);
        let frame = if a0.nrows() == 0 {
            Mat::identity(na, na)
        } else {
            let g = (&a0 * a0.transpose()).llt(Side::Lower).map_err(|e| ModalError::Numerical {
                stage: "Gram matrix of the joint rows AAᵀ".into(),
                reason: format!("matrix is not positive definite (dependent rows): {e:?}"),
            })?;
            Mat::<f64>::identity(na, na) - a0.transpose() * (g.inverse() * &a0)
        };
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for i in 0..na {
            let mut v = col(&frame, i);
            let n0 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            for _ in 0..2 {
                for c in &cols {
                    let d: f64 = c.iter().zip(&v).map(|(a, b)| a * b).sum();
                    v.iter_mut().zip(c).for_each(|(x, y)| *x -= d * y);
                }
            }
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if n0 > 0.0 && n > 1e-6 {
                cols.push(v.iter().map(|x| x / n).collect());
            }
        }
        let z0 = Mat::from_fn(na, cols.len(), |i, j| cols[j][i]);
        Self::on_fields(structure, basis, &cons, damping, inputs, (z0, Mat::identity(nb, nb)), true)
    }

    /// [`ExactJointsRom::new`] without the support reduction: the support rows stay rows of
    /// `A` (the general evaluation's path for supports that touch two links).
    #[cfg(test)]
    pub(crate) fn new_keeping_support_rows(
        structure: &Structure,
        basis: LinkBasis,
        damping: Option<&Mat<f64>>,
        inputs: &[Input],
    ) -> Result<Self> {
        let reduced = Self::new(structure, basis.clone(), damping, inputs)?;
        let cons = Constraints::new(structure, &basis)?;
        let z0 = match cons.support_reduction(&basis.cols1) {
            Some(n) => &n * &reduced.z0,
            None => reduced.z0.clone(),
        };
        let z2 = reduced.z2.clone();
        Self::on_fields(structure, basis, &cons, damping, inputs, (z0, z2), false)
    }

    /// The model with given orthonormal reduced coordinates `z0` (`na × m`, `A(ξ̄) z0 = 0`)
    /// and `z2` (`nb × m2`) on the link fields.
    pub fn with_coordinates(
        structure: &Structure,
        basis: LinkBasis,
        damping: Option<&Mat<f64>>,
        inputs: &[Input],
        z0: Mat<f64>,
        z2: Mat<f64>,
    ) -> Result<Self> {
        let (na, nb) = (basis.n1(), basis.n2());
        if z0.nrows() != na {
            return Err(shape("z0", (na, z0.ncols()), (z0.nrows(), z0.ncols())));
        }
        if z2.nrows() != nb {
            return Err(shape("z2", (nb, z2.ncols()), (z2.nrows(), z2.ncols())));
        }
        for (name, z) in [("z0", &z0), ("z2", &z2)] {
            let g = z.transpose() * z;
            let err = (0..g.nrows())
                .flat_map(|i| (0..g.ncols()).map(move |j| (i, j)))
                .fold(0.0f64, |m, (i, j)| {
                    m.max((g[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs())
                });
            if err > 1e-8 {
                return Err(invalid(name, err, "columns must be orthonormal (|ZᵀZ − I| ≤ 1e-8)"));
            }
        }
        let cons = Constraints::new(structure, &basis)?;
        let c = cons.rows_at_reference(na) * &z0;
        let viol = (0..c.nrows())
            .flat_map(|i| (0..c.ncols()).map(move |j| (i, j)))
            .fold(0.0f64, |m, (i, j)| m.max(c[(i, j)].abs()));
        if viol > 1e-8 {
            return Err(invalid(
                "z0",
                viol,
                "must satisfy the rows at the reference: |A(ξ̄) Z0| ≤ 1e-8",
            ));
        }
        Self::on_fields(structure, basis, &cons, damping, inputs, (z0, z2), true)
    }

    /// The model with coordinates `z0`, `z2` on `basis`, whose rows are `cons`. With
    /// `reduce`, where the support rows are each supported on one link (a support's rows are
    /// the values at one node), the fields are first reduced to
    /// `N = blockdiag_link(null S_link)` (orthonormal, `q1 = N q̂1`): every support row then
    /// vanishes on them, only the joint rows remain, and `Z0 → NᵀZ0` (the same coordinates
    /// `p`, since `S Z0 = 0` puts `Z0` in the range of `N`; theory.md §10.4).
    fn on_fields(
        structure: &Structure,
        basis: LinkBasis,
        cons: &Constraints,
        damping: Option<&Mat<f64>>,
        inputs: &[Input],
        (z0, z2): (Mat<f64>, Mat<f64>),
        reduce: bool,
    ) -> Result<Self> {
        let n = if reduce { cons.support_reduction(&basis.cols1) } else { None };
        let (basis, z0) = match n {
            Some(n) => {
                let z0 = n.transpose() * &z0;
                (basis.reduced(&n), z0)
            }
            None => (basis, z0),
        };
        let mut rom = Self::assemble(structure, basis, damping, inputs)?;
        rom.z0 = z0;
        rom.z2 = z2;
        rom.finish();
        Ok(rom)
    }

    fn assemble(
        structure: &Structure,
        basis: LinkBasis,
        damping: Option<&Mat<f64>>,
        inputs: &[Input],
    ) -> Result<Self> {
        let ops = AmbientOps::new(&basis, damping, inputs)?;
        let cons = Constraints::new(structure, &basis)?;
        let mut row_offsets = Vec::new();
        let mut r = cons.support.nrows();
        for j in &cons.joints {
            row_offsets.push(r);
            r += j.rows;
        }
        let layout = &basis.layout;
        let comps = layout.components;
        let k = comps.k();
        let rate_comps: Vec<(usize, usize)> = (0..k)
            .filter_map(|c| {
                let s = comps.spatial_index(c);
                (s >= 3).then_some((c, s - 3))
            })
            .collect();
        let mut rows: Vec<Mat<f64>> = cons.joints.iter().map(|j| j.e.clone()).collect();
        if let Some((b, n, _)) = cons.root {
            rows.push(Mat::from_fn(k, basis.n1(), |i, col| {
                basis.phi1[(layout.x1_index(b, n, i), col)]
            }));
        }
        let tracked = rows
            .into_iter()
            .map(|t| Tracked {
                rows_flat: flat(&t),
                z0: Vec::new(),
                s: flat(&(&t * cons.support.transpose())),
                e: cons.joints.iter().map(|j| flat(&(&t * j.e.transpose()))).collect(),
                rows: t,
            })
            .collect();
        let ss = flat(&(&cons.support * cons.support.transpose()));
        let planar = Planar::new(&basis, &cons, &rate_comps, &ops).map(Box::new);
        Ok(ExactJointsRom {
            ops,
            z0: Mat::zeros(basis.n1(), 0),
            z2: Mat::zeros(basis.n2(), 0),
            z2_identity: false,
            inputs: inputs.iter().map(|i| i.name.clone()).collect(),
            basis,
            tracked,
            ss,
            flat: FlatCopies {
                support: flat(&cons.support),
                e: cons.joints.iter().map(|j| flat(&j.e)).collect(),
                support_t: flat(&cons.support.transpose().to_owned()),
                e_t: cons.joints.iter().map(|j| flat(&j.e.transpose().to_owned())).collect(),
                ..FlatCopies::default()
            },
            cons,
            rate_comps,
            row_offsets,
            planar,
        })
    }

    /// Products with the final `Z0`, `Z2`.
    fn finish(&mut self) {
        for t in &mut self.tracked {
            t.z0 = flat(&(&t.rows * &self.z0));
        }
        self.flat.z0 = flat(&self.z0);
        self.flat.z2 = flat(&self.z2);
        let (nb, m2) = (self.z2.nrows(), self.z2.ncols());
        self.z2_identity = nb == m2
            && (0..nb).all(|i| (0..m2).all(|j| self.z2[(i, j)] == if i == j { 1.0 } else { 0.0 }));
        if let Some(pl) = &mut self.planar {
            pl.set_coordinates(&self.z0, &self.z2, self.z2_identity);
        }
    }

    /// The model-wide sizes the evaluation buffers depend on (the per-constraint ones follow).
    fn dims_head(&self) -> [usize; 6] {
        [
            self.basis.n1(),
            self.basis.n2(),
            self.n_p(),
            self.n_p2(),
            self.cons.support.nrows(),
            self.ops.scratch_len(),
        ]
    }

    /// The sizes the evaluation buffers depend on.
    pub(super) fn dims_key(&self) -> Vec<usize> {
        let mut key = self.dims_head().to_vec();
        key.extend(self.tracked.iter().map(|t| t.rows.nrows()));
        key.extend(self.cons.joints.iter().flat_map(|j| [j.rows, j.e.nrows()]));
        key.extend(self.ops.layout_key());
        key
    }

    /// Whether buffers sized for `key` fit this model (the ambient Jacobian buffer's zero
    /// entries included: [`AmbientOps::layout_key`]).
    pub(super) fn dims_match(&self, key: &[usize]) -> bool {
        let head = self.dims_head();
        let nt = self.tracked.len();
        let tail = head.len() + nt + 2 * self.n_joints();
        key.len() >= tail
            && self.ops.layout_key().eq(key[tail..].iter().copied())
            && key[..head.len()] == head
            && self.tracked.iter().zip(&key[head.len()..]).all(|(t, &k)| t.rows.nrows() == k)
            && self
                .cons
                .joints
                .iter()
                .zip(key[head.len() + nt..].chunks(2))
                .all(|(j, k)| k == [j.rows, j.e.nrows()])
    }

    pub(super) fn support_flat(&self) -> &[f64] {
        &self.flat.support
    }

    /// `Sᵀ` (`na × rs`), column-major.
    pub(super) fn support_t_flat(&self) -> &[f64] {
        &self.flat.support_t
    }

    /// `E_jᵀ` (`na × 2k`), column-major.
    pub(super) fn e_t_flat(&self, j: usize) -> &[f64] {
        &self.flat.e_t[j]
    }

    pub(super) fn e_flat(&self, j: usize) -> &[f64] {
        &self.flat.e[j]
    }

    pub(super) fn z0_flat(&self) -> &[f64] {
        &self.flat.z0
    }

    pub(super) fn z2_flat(&self) -> &[f64] {
        &self.flat.z2
    }

    /// The model's parts for its export: Galerkin operators, rows, `Z0`, `Z2` and the
    /// `(component, rate axis)` of the rotational components.
    pub(crate) fn parts(&self) -> ModelParts<'_> {
        (&self.ops, &self.cons, &self.z0, &self.z2, &self.rate_comps)
    }

    /// The link fields.
    pub fn basis(&self) -> &LinkBasis {
        &self.basis
    }

    /// `m`: reduced velocity coordinates.
    pub fn n_p(&self) -> usize {
        self.z0.ncols()
    }

    /// `m2`: reduced force coordinates.
    pub fn n_p2(&self) -> usize {
        self.z2.ncols()
    }

    /// Number of joints (two-end).
    pub fn n_joints(&self) -> usize {
        self.cons.joints.len()
    }

    /// Whether the state carries the root link's orientation.
    pub fn has_root(&self) -> bool {
        self.cons.root.is_some()
    }

    /// Offset of the root quaternion (when carried).
    pub fn root_offset(&self) -> usize {
        self.n_p() + self.n_p2()
    }

    /// Offset of joint `j`'s relative quaternion.
    pub fn joint_offset(&self, j: usize) -> usize {
        self.root_offset() + if self.has_root() { 4 } else { 0 } + 4 * j
    }

    /// State length.
    pub fn n_state(&self) -> usize {
        self.joint_offset(self.n_joints())
    }

    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        self.inputs.len()
    }

    /// Input names.
    pub fn input_names(&self) -> &[String] {
        &self.inputs
    }

    /// Joint names in state order.
    pub fn joint_names(&self) -> Vec<String> {
        self.cons.joints.iter().map(|j| j.name.clone()).collect()
    }

    fn reference_joints(&self) -> Vec<Vector4<f64>> {
        self.cons.joints.iter().map(|j| j.reference).collect()
    }

    /// The reference state: at rest, root and joints at their reference rotations.
    pub fn reference_state(&self) -> Vec<f64> {
        let mut x = vec![0.0; self.n_state()];
        if let Some((_, _, xi)) = self.cons.root {
            x[self.root_offset()..self.root_offset() + 4].copy_from_slice(xi.as_slice());
        }
        for (j, r) in self.reference_joints().iter().enumerate() {
            let o = self.joint_offset(j);
            x[o..o + 4].copy_from_slice(r.as_slice());
        }
        x
    }

    /// The joint quaternions of `x`, scaled to unit length (the rows' rotations).
    fn joint_xi(&self, x: &[f64]) -> Result<Vec<Vector4<f64>>> {
        let (mut xh, mut norm) = (Vec::new(), Vec::new());
        self.unit_state(x, &mut xh, &mut norm)?;
        Ok((0..self.n_joints())
            .map(|j| {
                Vector4::from_column_slice(&xh[self.joint_offset(j)..self.joint_offset(j) + 4])
            })
            .collect())
    }

    fn check(&self, x: &[f64], u: &[f64]) -> Result<()> {
        if x.len() != self.n_state() {
            return Err(shape("state x", (self.n_state(), 1), (x.len(), 1)));
        }
        if u.len() != self.n_inputs() {
            return Err(shape("input u", (self.n_inputs(), 1), (u.len(), 1)));
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(ModalError::NonFinite { what: "state x".into(), index: i });
        }
        if let Some(i) = u.iter().position(|v| !v.is_finite()) {
            return Err(ModalError::NonFinite { what: "input u".into(), index: i });
        }
        Ok(())
    }

    /// `Z(ξ)` (`na × m`) at the joint rotations of `x` (theory.md §10.4).
    fn null_basis(&self, x: &[f64]) -> Result<Mat<f64>> {
        let (na, m) = (self.basis.n1(), self.n_p());
        let (mut xh, mut norm) = (Vec::new(), Vec::new());
        self.unit_state(x, &mut xh, &mut norm)?;
        with_workspace(self, |ws| {
            self.frame_into(ws, &xh, true)?;
            Ok(Mat::from_fn(na, m, |i, j| ws.z[j * na + i]))
        })
    }

    /// Right-hand side `ẋ = f(x, u)` into `out`.
    pub fn rhs(&self, x: &[f64], u: &[f64], out: &mut [f64]) -> Result<()> {
        if out.len() != self.n_state() {
            return Err(shape("output", (self.n_state(), 1), (out.len(), 1)));
        }
        self.check(x, u)?;
        self.evaluate(x, u, out, None, true)
    }

    /// Right-hand side and exact Jacobians `∂f/∂x` (n × n) and `∂f/∂u` (n × inputs), both
    /// column-major (theory.md §10.5).
    pub fn rhs_and_jacobian(
        &self,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jx: &mut [f64],
        ju: &mut [f64],
    ) -> Result<()> {
        let n = self.n_state();
        let nu = self.n_inputs();
        if f.len() != n {
            return Err(shape("output", (n, 1), (f.len(), 1)));
        }
        if jx.len() != n * n {
            return Err(shape("Jacobian ∂f/∂x", (n, n), (jx.len(), 1)));
        }
        if ju.len() != n * nu {
            return Err(shape("Jacobian ∂f/∂u", (n, nu), (ju.len(), 1)));
        }
        self.check(x, u)?;
        self.evaluate(x, u, f, Some((jx, ju)), true)
    }

    /// Energy `½|p|² + ½|p2|²`.
    pub fn energy(&self, x: &[f64]) -> f64 {
        0.5 * x[..self.n_p() + self.n_p2()].iter().map(|v| v * v).sum::<f64>()
    }

    /// Link-field velocity coordinates `q1 = Z(ξ) p`.
    pub fn link_velocities(&self, x: &[f64]) -> Result<Vec<f64>> {
        self.check(x, &vec![0.0; self.n_inputs()])?;
        let z = self.null_basis(x)?;
        let m = self.n_p();
        Ok((0..z.nrows()).map(|i| (0..m).map(|j| z[(i, j)] * x[j]).sum()).collect())
    }

    /// `max |A(ξ) q1|`: the compatibility residual of the current velocities (round-off).
    pub fn compatibility_residual(&self, x: &[f64]) -> Result<f64> {
        let q1 = self.link_velocities(x)?;
        let a = self.cons.rows_full(&self.joint_xi(x)?, self.basis.n1());
        Ok((0..a.nrows())
            .map(|i| (0..a.ncols()).map(|j| a[(i, j)] * q1[j]).sum::<f64>())
            .fold(0.0f64, |m, v| m.max(v.abs())))
    }

    /// The relative quaternion of joint `j` in state `x`.
    pub fn joint_quaternion(&self, x: &[f64], j: usize) -> Vector4<f64> {
        let o = self.joint_offset(j);
        Vector4::from_column_slice(&x[o..o + 4])
    }

    /// The root link's quaternion in state `x` (when carried).
    pub fn root_quaternion(&self, x: &[f64]) -> Option<Vector4<f64>> {
        self.has_root().then(|| {
            let o = self.root_offset();
            Vector4::from_column_slice(&x[o..o + 4])
        })
    }

    /// The state of an FE configuration: full FE vector `x_fe` (theory.md §2) and node
    /// kinematics. Velocities and forces are projected (`q1 = Φ1ᵀB1X1`, `p = Zᵀq1`,
    /// `p2 = Z2ᵀΦ2ᵀB2X2`), rotations taken from the end nodes.
    pub fn project_fe(&self, x_fe: &[f64], kinematics: &[Kinematics]) -> Result<Vec<f64>> {
        let layout = &self.basis.layout;
        if x_fe.len() != layout.n_full() {
            return Err(shape("FE state", (layout.n_full(), 1), (x_fe.len(), 1)));
        }
        let (mut x1, mut x2) = (vec![0.0; layout.n1()], vec![0.0; layout.n2()]);
        for (i, v) in x_fe.iter().enumerate() {
            match layout.classify_full(i) {
                crate::layout::FullIndex::X1(p) => x1[p] = *v,
                crate::layout::FullIndex::X2(p) => x2[p] = *v,
                _ => {}
            }
        }
        let mut x = vec![0.0; self.n_state()];
        let node_xi = |b: usize, n: usize| -> Result<Vector4<f64>> {
            kinematics.get(b).and_then(|k| k.xi.get(n)).copied().ok_or_else(|| {
                invalid("kinematics", format!("beam {b} node {n}"), "missing in the FE kinematics")
            })
        };
        if let Some((b, n, _)) = self.cons.root {
            let o = self.root_offset();
            x[o..o + 4].copy_from_slice(node_xi(b, n)?.as_slice());
        }
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let (a, b) =
                (node_xi(jr.ends[0].0, jr.ends[0].1)?, node_xi(jr.ends[1].0, jr.ends[1].1)?);
            let o = self.joint_offset(j);
            x[o..o + 4].copy_from_slice(relative_quaternion(&a, &b).as_slice());
        }
        let z = self.null_basis(&x)?;
        let q1 = self.basis.coordinates1(Mat::from_fn(x1.len(), 1, |i, _| x1[i]).as_ref());
        let q2 = self.basis.coordinates2(Mat::from_fn(x2.len(), 1, |i, _| x2[i]).as_ref());
        let p = z.transpose() * &q1;
        let p2 = self.z2.transpose() * &q2;
        for i in 0..self.n_p() {
            x[i] = p[(i, 0)];
        }
        for i in 0..self.n_p2() {
            x[self.n_p() + i] = p2[(i, 0)];
        }
        Ok(x)
    }

    /// One implicit-midpoint step `x⁺ = x + dt f((x + x⁺)/2, u)` by Newton on the exact
    /// Jacobian, to `‖Δ‖∞ ≤ tol · max(1, ‖x‖∞)`. Returns the Newton iterations. The midpoint
    /// rule keeps `½|p|² + ½|p2|²` (undamped, unforced) and every `|ξ|` (their rates are skew in
    /// `ξ`), both quadratic invariants.
    pub fn midpoint_step(
        &self,
        x: &mut [f64],
        u: &[f64],
        dt: f64,
        tol: f64,
        max_iter: usize,
    ) -> Result<usize> {
        self.check(x, u)?;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid("dt", dt, "must be finite and > 0"));
        }
        let mut ju = vec![0.0; x.len() * self.n_inputs()];
        crate::midpoint::newton_step(
            x,
            dt,
            tol,
            max_iter,
            "exact-joints implicit midpoint",
            |mid, f, jx| self.rhs_and_jacobian(mid, u, f, jx, &mut ju),
        )
    }
}
