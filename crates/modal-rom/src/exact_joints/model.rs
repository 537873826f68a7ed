//! The exact-joints reduced model: state, right-hand side, exact Jacobian, implicit
//! midpoint (theory §10).
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
use crate::exact_joints::frame::{spd_inverse, NullFrame};
use crate::exact_joints::rows::{relative_quaternion, Constraints};
use crate::rom::Input;
use faer::linalg::solvers::Solve;
use faer::Mat;
use intrinsic_beam::Kinematics;
use multibody_constraints::Structure;
use nalgebra::{Matrix4, Vector3, Vector4};

/// `U(ω)` of eq. (8): `U(ω)ξ = ½ ξ ⊗ (0, ω)`.
fn u_right(w: &Vector3<f64>) -> Matrix4<f64> {
    Matrix4::new(
        0.0, -w.x, -w.y, -w.z, //
        w.x, 0.0, w.z, -w.y, //
        w.y, -w.z, 0.0, w.x, //
        w.z, w.y, -w.x, 0.0,
    ) * 0.5
}

/// `Ū(ω)`: `Ū(ω)ξ = ½ (0, ω) ⊗ ξ`.
fn u_left(w: &Vector3<f64>) -> Matrix4<f64> {
    Matrix4::new(
        0.0, -w.x, -w.y, -w.z, //
        w.x, 0.0, -w.z, w.y, //
        w.y, w.z, 0.0, -w.x, //
        w.z, -w.y, w.x, 0.0,
    ) * 0.5
}

/// Body-rate rows (`3 × na`) of the link fields at a node.
fn rate_rows(basis: &LinkBasis, b: usize, n: usize) -> Mat<f64> {
    let layout = &basis.layout;
    let comps = layout.components;
    let mut r = Mat::<f64>::zeros(3, basis.n1());
    for c in 0..comps.k() {
        let s = comps.spatial_index(c);
        if s >= 3 {
            let idx = layout.x1_index(b, n, c);
            for col in 0..basis.n1() {
                r[(s - 3, col)] = basis.phi1[(idx, col)];
            }
        }
    }
    r
}

fn mat_vec(m: &Mat<f64>, v: &[f64]) -> Vec<f64> {
    (0..m.nrows()).map(|i| (0..m.ncols()).map(|j| m[(i, j)] * v[j]).sum()).collect()
}

fn mat_tvec(m: &Mat<f64>, v: &[f64]) -> Vec<f64> {
    (0..m.ncols()).map(|j| (0..m.nrows()).map(|i| m[(i, j)] * v[i]).sum()).collect()
}

fn rate(r: &Mat<f64>, q1: &[f64]) -> Vector3<f64> {
    let v = mat_vec(r, q1);
    Vector3::new(v[0], v[1], v[2])
}

fn col(m: &Mat<f64>, j: usize) -> Vec<f64> {
    (0..m.nrows()).map(|i| m[(i, j)]).collect()
}

/// The exact-joints reduced model (module docs; theory §10).
#[derive(Clone, Debug)]
pub struct ExactJointsRom {
    basis: LinkBasis,
    ops: AmbientOps,
    cons: Constraints,
    z0: Mat<f64>,
    z2: Mat<f64>,
    inputs: Vec<String>,
    root_rate: Option<Mat<f64>>,
    /// `(rows of end a, rows of end b)` per joint.
    joint_rates: Vec<(Mat<f64>, Mat<f64>)>,
    /// First row of each joint in `A`.
    row_offsets: Vec<usize>,
}

/// Everything one evaluation computes.
struct Eval {
    frame: NullFrame,
    /// `∂A/∂ξ_jc` as full `r × na` matrices, `[joint][c]`.
    da: Vec<[Mat<f64>; 4]>,
    q1: Vec<f64>,
    q2: Vec<f64>,
    f1: Vec<f64>,

    adot: Mat<f64>,
    xi_dot: Vec<Vector4<f64>>,
    root_dot: Option<Vector4<f64>>,
    rhs: Vec<f64>,
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
        let mut rom = Self::assemble(structure, basis, damping, inputs)?;
        let a0 = rom.rows_at(&rom.reference_joints()).0;
        let na = rom.basis.n1();
        let frame = if a0.nrows() == 0 {
            Mat::identity(na, na)
        } else {
            let g = spd_inverse(&(&a0 * a0.transpose()), "Gram matrix of the joint rows AAᵀ")?;
            Mat::<f64>::identity(na, na) - a0.transpose() * (&g * &a0)
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
        rom.z0 = Mat::from_fn(na, cols.len(), |i, j| cols[j][i]);
        rom.z2 = Mat::identity(nb, nb);
        Ok(rom)
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
        let mut rom = Self::assemble(structure, basis, damping, inputs)?;
        let a0 = rom.rows_at(&rom.reference_joints()).0;
        let c = &a0 * &z0;
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
        rom.z0 = z0;
        rom.z2 = z2;
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
        let root_rate = cons.root.map(|(b, n, _)| rate_rows(&basis, b, n));
        let joint_rates = cons
            .joints
            .iter()
            .map(|j| {
                (
                    rate_rows(&basis, j.ends[0].0, j.ends[0].1),
                    rate_rows(&basis, j.ends[1].0, j.ends[1].1),
                )
            })
            .collect();
        let mut row_offsets = Vec::new();
        let mut r = cons.support.nrows();
        for j in &cons.joints {
            row_offsets.push(r);
            r += j.a_c.nrows();
        }
        Ok(ExactJointsRom {
            ops,
            cons,
            z0: Mat::zeros(basis.n1(), 0),
            z2: Mat::zeros(basis.n2(), 0),
            inputs: inputs.iter().map(|i| i.name.clone()).collect(),
            basis,
            root_rate,
            joint_rates,
            row_offsets,
        })
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
        self.root_rate.is_some()
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

    fn joint_xi(&self, x: &[f64]) -> Vec<Vector4<f64>> {
        (0..self.n_joints())
            .map(|j| Vector4::from_column_slice(&x[self.joint_offset(j)..self.joint_offset(j) + 4]))
            .collect()
    }

    /// `A(ξ)` and `∂A/∂ξ_jc` (full rows).
    fn rows_at(&self, xis: &[Vector4<f64>]) -> (Mat<f64>, Vec<[Mat<f64>; 4]>) {
        let na = self.basis.n1();
        let r = self.cons.n_rows();
        let mut a = Mat::<f64>::zeros(r, na);
        let rs = self.cons.support.nrows();
        for i in 0..rs {
            for c in 0..na {
                a[(i, c)] = self.cons.support[(i, c)];
            }
        }
        let mut das = Vec::new();
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let (aj, daj) = jr.at(&xis[j]);
            let o = self.row_offsets[j];
            let mut full: [Mat<f64>; 4] = std::array::from_fn(|_| Mat::zeros(r, na));
            for i in 0..aj.nrows() {
                for c in 0..na {
                    a[(o + i, c)] = aj[(i, c)];
                    for (f, d) in full.iter_mut().zip(&daj) {
                        f[(o + i, c)] = d[(i, c)];
                    }
                }
            }
            das.push(full);
        }
        (a, das)
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

    fn evaluate(&self, x: &[f64], u: &[f64]) -> Result<Eval> {
        self.check(x, u)?;
        let (m, m2) = (self.n_p(), self.n_p2());
        let xis = self.joint_xi(x);
        let (a, da) = self.rows_at(&xis);
        let frame = NullFrame::new(a, &self.z0)?;
        let p = &x[..m];
        let q1 = mat_vec(&frame.z, p);
        let q2 = mat_vec(&self.z2, &x[m..m + m2]);
        let (mut f1, mut f2) = (vec![0.0; q1.len()], vec![0.0; q2.len()]);
        self.ops.rhs(&q1, &q2, u, &mut f1, &mut f2);
        let mut adot = Mat::<f64>::zeros(frame.a.nrows(), frame.a.ncols());
        let mut xi_dot = Vec::new();
        for (j, (ra, rb)) in self.joint_rates.iter().enumerate() {
            let d = (u_right(&rate(rb, &q1)) - u_left(&rate(ra, &q1))) * xis[j];
            for c in 0..4 {
                if d[c] != 0.0 {
                    adot += &da[j][c] * d[c];
                }
            }
            xi_dot.push(d);
        }
        let root_dot = self.root_rate.as_ref().map(|r| {
            let o = self.root_offset();
            u_right(&rate(r, &q1)) * Vector4::from_column_slice(&x[o..o + 4])
        });
        let kp = mat_vec(&frame.k_of(&adot), p);
        let ztf = mat_tvec(&frame.z, &f1);
        let mut rhs = vec![0.0; self.n_state()];
        for i in 0..m {
            rhs[i] = ztf[i] - kp[i];
        }
        let z2f = mat_tvec(&self.z2, &f2);
        rhs[m..m + m2].copy_from_slice(&z2f);
        if let Some(d) = root_dot {
            let o = self.root_offset();
            rhs[o..o + 4].copy_from_slice(d.as_slice());
        }
        for (j, d) in xi_dot.iter().enumerate() {
            let o = self.joint_offset(j);
            rhs[o..o + 4].copy_from_slice(d.as_slice());
        }
        Ok(Eval { frame, da, q1, q2, f1, adot, xi_dot, root_dot, rhs })
    }

    /// Right-hand side `ẋ = f(x, u)` into `out`.
    pub fn rhs(&self, x: &[f64], u: &[f64], out: &mut [f64]) -> Result<()> {
        if out.len() != self.n_state() {
            return Err(shape("output", (self.n_state(), 1), (out.len(), 1)));
        }
        let e = self.evaluate(x, u)?;
        out.copy_from_slice(&e.rhs);
        Ok(())
    }

    /// Right-hand side and exact Jacobians `∂f/∂x` (n × n) and `∂f/∂u` (n × inputs), both
    /// column-major (theory §10.5).
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
        let e = self.evaluate(x, u)?;
        f.copy_from_slice(&e.rhs);
        jx.fill(0.0);
        ju.fill(0.0);
        let (m, m2) = (self.n_p(), self.n_p2());
        let na = self.basis.n1();
        let fr = &e.frame;
        let p = &x[..m];
        let xis = self.joint_xi(x);
        let root_xi = self.has_root().then(|| {
            let o = self.root_offset();
            Vector4::from_column_slice(&x[o..o + 4])
        });
        let jf = self.ops.jacobian(&e.q1, &e.q2);
        let nb = e.q2.len();
        let j11 = Mat::from_fn(na, na, |i, j| jf[(i, j)]);
        let j12 = Mat::from_fn(na, nb, |i, j| jf[(i, na + j)]);
        let j21 = Mat::from_fn(nb, na, |i, j| jf[(na + i, j)]);
        let j22 = Mat::from_fn(nb, nb, |i, j| jf[(na + i, na + j)]);
        let k = fr.k_of(&e.adot);
        let ztj11 = fr.z.transpose() * &j11;
        let z2tj21 = self.z2.transpose() * &j21;
        let mut set = |r: usize, c: usize, v: f64| jx[c * n + r] += v;
        // quaternion rate changes for a change dq1 of q1
        let xi_rate_change = |dq1: &[f64]| -> (Option<Vector4<f64>>, Vec<Vector4<f64>>) {
            let root = root_xi.map(|xr| u_right(&rate(self.root_rate.as_ref().unwrap(), dq1)) * xr);
            let joints = self
                .joint_rates
                .iter()
                .enumerate()
                .map(|(j, (ra, rb))| (u_right(&rate(rb, dq1)) - u_left(&rate(ra, dq1))) * xis[j])
                .collect();
            (root, joints)
        };
        let adot_of = |dxi: &[Vector4<f64>]| -> Mat<f64> {
            let mut a = Mat::<f64>::zeros(fr.a.nrows(), na);
            for (j, d) in dxi.iter().enumerate() {
                for c in 0..4 {
                    if d[c] != 0.0 {
                        a += &e.da[j][c] * d[c];
                    }
                }
            }
            a
        };
        let put_xi = |set: &mut dyn FnMut(usize, usize, f64),
                      c: usize,
                      root: Option<Vector4<f64>>,
                      joints: &[Vector4<f64>]| {
            if let Some(d) = root {
                for i in 0..4 {
                    set(self.root_offset() + i, c, d[i]);
                }
            }
            for (j, d) in joints.iter().enumerate() {
                for i in 0..4 {
                    set(self.joint_offset(j) + i, c, d[i]);
                }
            }
        };
        // columns of p
        for kc in 0..m {
            let ze = col(&fr.z, kc);
            let a = mat_vec(&ztj11, &ze);
            let (root, joints) = xi_rate_change(&ze);
            let kk = fr.k_of(&adot_of(&joints));
            let kkp = mat_vec(&kk, p);
            for i in 0..m {
                set(i, kc, a[i] - k[(i, kc)] - kkp[i]);
            }
            let b = mat_vec(&z2tj21, &ze);
            for i in 0..m2 {
                set(m + i, kc, b[i]);
            }
            put_xi(&mut set, kc, root, &joints);
        }
        // columns of p2
        let c12 = fr.z.transpose() * &j12 * &self.z2;
        let c22 = self.z2.transpose() * &j22 * &self.z2;
        for kc in 0..m2 {
            for i in 0..m {
                set(i, m + kc, c12[(i, kc)]);
            }
            for i in 0..m2 {
                set(m + i, m + kc, c22[(i, kc)]);
            }
        }
        // columns of the root quaternion
        if let (Some(r), Some(_)) = (&self.root_rate, e.root_dot) {
            let ur = u_right(&rate(r, &e.q1));
            let o = self.root_offset();
            for c in 0..4 {
                for i in 0..4 {
                    set(o + i, o + c, ur[(i, c)]);
                }
            }
        }
        // columns of the joint quaternions
        for j in 0..self.n_joints() {
            let (ra, rb) = &self.joint_rates[j];
            let mj = u_right(&rate(rb, &e.q1)) - u_left(&rate(ra, &e.q1));
            for c in 0..4 {
                let ac = &e.da[j][c];
                let (zc, lam_t) = fr.z_dot(ac);
                let q1c = mat_vec(&zc, p);
                let (root, mut joints) = xi_rate_change(&q1c);
                for i in 0..4 {
                    joints[j][i] += mj[(i, c)];
                }
                // ∂Ȧ: second derivatives of A times ξ̇, plus ∂A times ∂ξ̇
                let mut dadot = adot_of(&joints);
                let jr = &self.cons.joints[j];
                let o = self.row_offsets[j];
                for c2 in 0..4 {
                    let s = e.xi_dot[j][c2];
                    if s == 0.0 {
                        continue;
                    }
                    let sec = jr.second(c, c2);
                    for i in 0..sec.nrows() {
                        for cc in 0..na {
                            dadot[(o + i, cc)] += sec[(i, cc)] * s;
                        }
                    }
                }
                let dk = fr.k_derivative(&e.adot, &dadot, ac, &zc, &lam_t);
                let dkp = mat_vec(&dk, p);
                let zcf = mat_tvec(&zc, &e.f1);
                let jq = mat_vec(&ztj11, &q1c);
                let kc = self.joint_offset(j) + c;
                for i in 0..m {
                    set(i, kc, zcf[i] + jq[i] - dkp[i]);
                }
                let b = mat_vec(&z2tj21, &q1c);
                for i in 0..m2 {
                    set(m + i, kc, b[i]);
                }
                put_xi(&mut set, kc, root, &joints);
            }
        }
        // inputs
        let zb = fr.z.transpose() * &self.ops.b_u;
        for c in 0..nu {
            for i in 0..m {
                ju[c * n + i] = zb[(i, c)];
            }
        }
        Ok(())
    }

    /// Energy `½|p|² + ½|p2|²`.
    pub fn energy(&self, x: &[f64]) -> f64 {
        0.5 * x[..self.n_p() + self.n_p2()].iter().map(|v| v * v).sum::<f64>()
    }

    /// Link-field velocity coordinates `q1 = Z(ξ) p`.
    pub fn link_velocities(&self, x: &[f64]) -> Result<Vec<f64>> {
        let u = vec![0.0; self.n_inputs()];
        Ok(self.evaluate(x, &u)?.q1)
    }

    /// `max |A(ξ) q1|`: the compatibility residual of the current velocities (round-off).
    pub fn compatibility_residual(&self, x: &[f64]) -> Result<f64> {
        let u = vec![0.0; self.n_inputs()];
        let e = self.evaluate(x, &u)?;
        let r = mat_vec(&e.frame.a, &e.q1);
        Ok(r.iter().fold(0.0f64, |m, v| m.max(v.abs())))
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
        let (a, _) = self.rows_at(&self.joint_xi(&x));
        let frame = NullFrame::new(a, &self.z0)?;
        let q1 = self.basis.coordinates1(Mat::from_fn(x1.len(), 1, |i, _| x1[i]).as_ref());
        let q2 = self.basis.coordinates2(Mat::from_fn(x2.len(), 1, |i, _| x2[i]).as_ref());
        let p = frame.z.transpose() * &q1;
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
        let n = self.n_state();
        let x0 = x.to_vec();
        let mut z = x0.clone();
        let mut mid = vec![0.0; n];
        let mut f = vec![0.0; n];
        let mut jx = vec![0.0; n * n];
        let mut ju = vec![0.0; n * self.n_inputs()];
        let scale = x0.iter().fold(1.0f64, |a, v| a.max(v.abs()));
        for it in 1..=max_iter {
            for i in 0..n {
                mid[i] = 0.5 * (x0[i] + z[i]);
            }
            self.rhs_and_jacobian(&mid, u, &mut f, &mut jx, &mut ju)?;
            let mut a = Mat::<f64>::from_fn(n, n, |i, j| -0.5 * dt * jx[j * n + i]);
            for i in 0..n {
                a[(i, i)] += 1.0;
            }
            let mut r = Mat::<f64>::from_fn(n, 1, |i, _| -(z[i] - x0[i] - dt * f[i]));
            a.partial_piv_lu().solve_in_place(r.as_mut());
            let mut step = 0.0f64;
            for i in 0..n {
                z[i] += r[(i, 0)];
                step = step.max(r[(i, 0)].abs());
            }
            if !step.is_finite() {
                return Err(ModalError::Numerical {
                    stage: "exact-joints implicit midpoint".into(),
                    reason: "non-finite update".into(),
                });
            }
            if step <= tol * scale {
                x.copy_from_slice(&z);
                return Ok(it);
            }
        }
        Err(ModalError::Numerical {
            stage: "exact-joints implicit midpoint".into(),
            reason: format!("no convergence in {max_iter} iterations"),
        })
    }
}
