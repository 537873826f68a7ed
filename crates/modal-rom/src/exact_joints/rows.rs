//! Velocity-compatibility rows (11) on per-link fields at the current relative rotation of
//! each joint (theory.md §10.3).
//!
//! For a two-end joint with ends `a` (its first end) and `b`, let `R = T_aᵀT_b` be the relative
//! rotation of the two end frames. Evaluating the joint's rows with end rotations `(I, R)`
//! (end `a`'s frame as the common frame) gives rows whose every coefficient is linear in the
//! entries of `R`: `u_a = d`, `u_b = Rᵀd` (global or end-0 axes), `u_a = R d` (end-1 axes), or
//! constant (each end's own axes). So on the link fields `A(R) = A_c + Σ_pq R_pq A_pq`, checked
//! at a random rotation when built. This is exactly the plant's row set up to a rotation of
//! rows among rigid directions of one part, which leaves the constraint unchanged; a part that
//! mixes rigid and free directions in the global frame would depend on the absolute rotation
//! and is rejected. Supports (the ground side fixed) use the same rule with the support's
//! reference rotation and must not depend on the end's rotation: their rows are constant.
//!
//! `R(ξ) = (ξ0² − |ξv|²) I + 2 ξv ξvᵀ + 2 ξ0 ξ̃v`, eq. (9) written homogeneous of degree 2, so
//! that `∂²R/∂ξ∂ξ` is constant.

use crate::error::{invalid, Result};
use crate::exact_joints::ambient::LinkBasis;
use faer::traits::pulp::{Arch, Simd, WithSimd};
use faer::Mat;
use intrinsic_beam::operators::tilde;
use intrinsic_beam::rotation::rotation;
use multibody_constraints::Structure;
use multibody_constraints::{rows, Frame, Freedom, Part, RowKind};
use nalgebra::{Matrix3, Vector3, Vector4};

/// `R(ξ)` (homogeneous form) and `∂R/∂ξ_c`, `c = 0…3`.
pub(crate) fn rotation_and_derivatives(xi: &Vector4<f64>) -> (Matrix3<f64>, [Matrix3<f64>; 4]) {
    let v = Vector3::new(xi[1], xi[2], xi[3]);
    let r = Matrix3::identity() * (xi[0] * xi[0] - v.norm_squared())
        + v * v.transpose() * 2.0
        + tilde(&v) * (2.0 * xi[0]);
    let mut d = [Matrix3::zeros(); 4];
    d[0] = Matrix3::identity() * (2.0 * xi[0]) + tilde(&v) * 2.0;
    for k in 0..3 {
        let e = Vector3::ith(k, 1.0);
        d[k + 1] = Matrix3::identity() * (-2.0 * v[k])
            + (e * v.transpose() + v * e.transpose()) * 2.0
            + tilde(&e) * (2.0 * xi[0]);
    }
    (r, d)
}

/// `∂²R/∂ξ_c∂ξ_d` (constant).
pub(crate) fn rotation_second(c: usize, d: usize) -> Matrix3<f64> {
    match (c, d) {
        (0, 0) => Matrix3::identity() * 2.0,
        (0, k) | (k, 0) => tilde(&Vector3::ith(k - 1, 1.0)) * 2.0,
        (k, l) => {
            let (ek, el) = (Vector3::ith(k - 1, 1.0), Vector3::ith(l - 1, 1.0));
            let diag = if k == l { -2.0 } else { 0.0 };
            Matrix3::identity() * diag + (ek * el.transpose() + el * ek.transpose()) * 2.0
        }
    }
}

/// One two-end joint's rows on the link fields, `A_j(ξ) = C(R(ξ)) E`: `E` (`2k × na`) holds the
/// fields' values at the two end nodes (end `a` then end `b`, local components) and the
/// coefficients `C(R) = C_c + Σ_pq R_pq C_pq` (`r_j × 2k`) are linear in `R`.
#[derive(Clone, Debug)]
pub(crate) struct JointRows {
    pub name: String,
    /// `(beam, node)` of ends `a` and `b`.
    pub ends: [(usize, usize); 2],
    /// `E` (`2k × na`).
    pub e: Mat<f64>,
    /// `C_c` (`r × 2k`, column-major).
    pub c_c: Vec<f64>,
    /// `C_pq` (`r × 2k`, column-major), index `3p + q`.
    pub c_pq: Vec<Vec<f64>>,
    /// Rows `r`.
    pub rows: usize,
    /// `∂²C/∂ξ_c∂ξ_d` (constant, `r × 2k`), index `4c + d`.
    pub c2: Vec<Vec<f64>>,
    /// Reference relative rotation `ξ̄_a* ⊗ ξ̄_b`.
    pub reference: Vector4<f64>,
}

impl JointRows {
    /// `C(ξ)` into `c` and `∂C/∂ξ_d` into `dc[d]` (each `r × 2k`, column-major).
    pub fn coefficients(&self, xi: &Vector4<f64>, c: &mut [f64], dc: &mut [&mut [f64]; 4]) {
        Arch::new().dispatch(Coefficients { rows: self, xi, c, dc });
    }

    /// `∂²C/∂ξ_c∂ξ_d` (constant).
    fn second(c_pq: &[Vec<f64>], c: usize, d: usize) -> Vec<f64> {
        let r2 = rotation_second(c, d);
        let mut out = vec![0.0; c_pq[0].len()];
        for p in 0..3 {
            for q in 0..3 {
                let w = r2[(p, q)];
                if w != 0.0 {
                    out.iter_mut().zip(&c_pq[3 * p + q]).for_each(|(x, y)| *x += w * y);
                }
            }
        }
        out
    }

    /// `A(ξ) = C(ξ) E` (`r × na`).
    pub fn rows_at(&self, xi: &Vector4<f64>) -> Mat<f64> {
        let kk = self.e.nrows();
        let mut c = vec![0.0; self.rows * kk];
        let mut d: [Vec<f64>; 4] = std::array::from_fn(|_| vec![0.0; self.rows * kk]);
        let [d0, d1, d2, d3] = &mut d;
        self.coefficients(xi, &mut c, &mut [d0, d1, d2, d3]);
        let cm = Mat::from_fn(self.rows, kk, |i, j| c[j * self.rows + i]);
        &cm * &self.e
    }
}

/// All compatibility rows of a structure on its link fields.
#[derive(Clone, Debug)]
pub(crate) struct Constraints {
    /// Constant support rows, orthonormal row basis (`rs × na`).
    pub support: Mat<f64>,
    /// `(beam, node, reference quaternion)` of the first support's end: the root link's
    /// orientation state.
    pub root: Option<(usize, usize, Vector4<f64>)>,
    pub joints: Vec<JointRows>,
}

fn quat_conj(q: &Vector4<f64>) -> Vector4<f64> {
    Vector4::new(q[0], -q[1], -q[2], -q[3])
}

/// Hamilton product `p ⊗ q` (scalar first).
pub(crate) fn quat_mul(p: &Vector4<f64>, q: &Vector4<f64>) -> Vector4<f64> {
    let (p0, pv) = (p[0], Vector3::new(p[1], p[2], p[3]));
    let (q0, qv) = (q[0], Vector3::new(q[1], q[2], q[3]));
    let v = qv * p0 + pv * q0 + pv.cross(&qv);
    Vector4::new(p0 * q0 - pv.dot(&qv), v.x, v.y, v.z)
}

/// Relative rotation `ξ_a* ⊗ ξ_b` (`T(ξ) = T_aᵀT_b`).
pub fn relative_quaternion(xa: &Vector4<f64>, xb: &Vector4<f64>) -> Vector4<f64> {
    quat_mul(&quat_conj(xa), xb)
}

impl Constraints {
    pub fn new(structure: &Structure, basis: &LinkBasis) -> Result<Self> {
        let layout = &basis.layout;
        let comps = layout.components;
        let k = comps.k();
        let na = basis.n1();
        let mut support_rows: Vec<Vec<f64>> = Vec::new();
        let mut joints = Vec::new();
        let mut root = None;
        for j in structure.joints() {
            // Parts mixing rigid and free global axes depend on the absolute rotation.
            for part in [Part::Linear, Part::Angular] {
                let ax: Vec<_> = j.axes.iter().filter(|a| a.part == part).collect();
                let mixed = ax.iter().any(|a| a.freedom == Freedom::Rigid)
                    && ax.iter().any(|a| a.freedom == Freedom::Free);
                let global = ax.iter().any(|a| a.frame == Frame::Global);
                if mixed && global && !(j.ground && k == 3 && part == Part::Angular) {
                    return Err(invalid(
                        format!("joint `{}`", j.name),
                        format!("{part:?}"),
                        "rigid and free global axes in one part depend on the absolute rotation",
                    ));
                }
            }
            let nodes: Vec<(usize, usize)> =
                j.ends.iter().map(|&(b, e)| (b, structure.end_node(b, e))).collect();
            // coefficients of the rows on the end nodes' components (`r × 2k`)
            let coeffs = |rots: &[Matrix3<f64>]| -> Mat<f64> {
                let rs: Vec<_> = rows(&j.axes, &j.signs, j.ground, rots)
                    .into_iter()
                    .filter(|r| r.kind == RowKind::Compatibility)
                    .collect();
                let mut c = Mat::<f64>::zeros(rs.len(), nodes.len() * k);
                for (ri, row) in rs.iter().enumerate() {
                    for t in row.terms.iter().filter(|t| t.on_velocity) {
                        for comp in 0..k {
                            let s = comps.spatial_index(comp);
                            let coef = match (t.part, s < 3) {
                                (Part::Linear, true) => t.direction[s],
                                (Part::Angular, false) => t.direction[s - 3],
                                _ => 0.0,
                            };
                            c[(ri, t.end * k + comp)] += coef;
                        }
                    }
                }
                c
            };
            // the end nodes' field values (`2k × na`)
            let e = Mat::from_fn(nodes.len() * k, na, |i, col| {
                let (b, n) = nodes[i / k];
                basis.phi1[(layout.x1_index(b, n, i % k), col)]
            });
            let assemble = |rots: &[Matrix3<f64>]| -> Mat<f64> { coeffs(rots) * &e };
            if j.ground {
                let (b, n) = nodes[0];
                let xi = layout.beams[b].xi(n);
                if root.is_none() {
                    root = Some((b, n, xi));
                }
                let a = assemble(&[rotation(&xi)]);
                for r in 0..a.nrows() {
                    support_rows.push((0..na).map(|c| a[(r, c)]).collect());
                }
                continue;
            }
            if nodes.len() != 2 {
                return Err(invalid(
                    format!("joint `{}` ends", j.name),
                    nodes.len(),
                    "the exact-joints model needs two-end joints",
                ));
            }
            let c_c = coeffs(&[Matrix3::identity(), Matrix3::zeros()]);
            let mut c_pq = Vec::with_capacity(9);
            for p in 0..3 {
                for q in 0..3 {
                    let mut r = Matrix3::zeros();
                    r[(p, q)] = 1.0;
                    c_pq.push(coeffs(&[Matrix3::identity(), r]) - &c_c);
                }
            }
            let a_c = &c_c * &e;
            let a_pq: Vec<Mat<f64>> = c_pq.iter().map(|c| c * &e).collect();
            let (xa, xb) =
                (layout.beams[nodes[0].0].xi(nodes[0].1), layout.beams[nodes[1].0].xi(nodes[1].1));
            let reference = relative_quaternion(&xa, &xb);
            // drop rows that vanish on the fields for every rotation
            let scale = a_pq.iter().chain([&a_c]).fold(0.0f64, |m, a| {
                (0..a.nrows()).fold(m, |m, r| (0..na).fold(m, |m, c| m.max(a[(r, c)].abs())))
            });
            let keep: Vec<usize> = (0..a_c.nrows())
                .filter(|&r| {
                    a_pq.iter()
                        .chain([&a_c])
                        .any(|a| (0..na).any(|c| a[(r, c)].abs() > 1e-12 * scale))
                })
                .collect();
            let kk = e.nrows();
            let pick = |c: &Mat<f64>| -> Vec<f64> {
                (0..kk).flat_map(|col| keep.iter().map(move |&r| c[(r, col)])).collect()
            };
            let c_pq: Vec<Vec<f64>> = c_pq.iter().map(pick).collect();
            let c2 = (0..16).map(|cd| JointRows::second(&c_pq, cd / 4, cd % 4)).collect();
            let rows = JointRows {
                name: j.name.clone(),
                ends: [nodes[0], nodes[1]],
                c_c: pick(&c_c),
                c_pq,
                c2,
                rows: keep.len(),
                e: e.clone(),
                reference,
            };
            // linearity in R, checked at a rotation away from the axes
            let test = Vector4::new(0.8, 0.3, -0.4, 0.2).normalize();
            let direct = assemble(&[Matrix3::identity(), rotation(&test)]);
            let lin = rows.rows_at(&test);
            let err = (0..lin.nrows())
                .flat_map(|r| (0..na).map(move |c| (r, c)))
                .fold(0.0f64, |m, (r, c)| m.max((lin[(r, c)] - direct[(keep[r], c)]).abs()));
            if err > 1e-10 * scale.max(1.0) {
                return Err(invalid(
                    format!("joint `{}`", j.name),
                    err,
                    "rows are not linear in the relative rotation",
                ));
            }
            joints.push(rows);
        }
        // orthonormal basis of the support rows' span (constant)
        let rs = support_rows.len();
        let support = if rs == 0 {
            Mat::zeros(0, na)
        } else {
            let a = Mat::from_fn(rs, na, |r, c| support_rows[r][c]);
            let gram = &a * a.transpose();
            let eig = gram.self_adjoint_eigen(faer::Side::Lower).map_err(|e| {
                crate::error::ModalError::Numerical {
                    stage: "support rows".into(),
                    reason: format!("{e:?}"),
                }
            })?;
            let s = eig.S().column_vector();
            let u = eig.U();
            let smax = (0..rs).map(|i| s[i]).fold(0.0f64, f64::max);
            // rows are unit-direction sums of field values: compare with the fields' size
            let size = (0..basis.phi1.nrows())
                .flat_map(|i| (0..na).map(move |c| (i, c)))
                .fold(0.0f64, |m, (i, c)| m.max(basis.phi1[(i, c)].abs()));
            let keep: Vec<usize> = (0..rs)
                .filter(|&i| smax > 0.0 && s[i] > 1e-16 * smax && s[i] > (1e-9 * size).powi(2))
                .collect();
            let mut out = Mat::<f64>::zeros(keep.len(), na);
            for (o, &e) in keep.iter().enumerate() {
                for r in 0..rs {
                    let w = u[(r, e)] / s[e].sqrt();
                    for c in 0..na {
                        out[(o, c)] += w * a[(r, c)];
                    }
                }
            }
            out
        };
        Ok(Constraints { support, root, joints })
    }

    /// Total rows.
    pub fn n_rows(&self) -> usize {
        self.support.nrows() + self.joints.iter().map(|j| j.rows).sum::<usize>()
    }

    /// `A(ξ)` (`r × na`) at joint rotations `xis` (one per joint): support rows, then each
    /// joint's `C_j(ξ_j) E_j`.
    pub fn rows_full(&self, xis: &[Vector4<f64>], na: usize) -> Mat<f64> {
        let mut a = Mat::<f64>::zeros(self.n_rows(), na);
        let mut o = self.support.nrows();
        a.as_mut().subrows_mut(0, o).copy_from(&self.support);
        for (j, xi) in self.joints.iter().zip(xis) {
            a.as_mut().subrows_mut(o, j.rows).copy_from(j.rows_at(xi));
            o += j.rows;
        }
        a
    }

    /// `A(ξ̄)` at the joints' reference rotations.
    pub fn rows_at_reference(&self, na: usize) -> Mat<f64> {
        let xis: Vec<_> = self.joints.iter().map(|j| j.reference).collect();
        self.rows_full(&xis, na)
    }

    /// `N = blockdiag_link(null S_link)` (`na × n`, orthonormal columns) for the support rows
    /// `S` on fields whose links occupy the column ranges `links`, or `None` when there are
    /// no support rows or one of them touches two links. Every support row vanishes on the
    /// reduced fields `Φ1 N`.
    pub fn support_reduction(&self, links: &[(usize, usize)]) -> Option<Mat<f64>> {
        let s = &self.support;
        if s.nrows() == 0 {
            return None;
        }
        let na = s.ncols();
        let link_of = |c: usize| links.iter().position(|r| c >= r.0 && c < r.1);
        for i in 0..s.nrows() {
            let mut touched = (0..na).filter(|&c| s[(i, c)] != 0.0).map(link_of);
            if let Some(first) = touched.next() {
                if touched.any(|l| l != first) {
                    return None;
                }
            }
        }
        let mut blocks: Vec<Mat<f64>> = Vec::new();
        for &(c0, c1) in links {
            let kl = c1 - c0;
            let mut p = Mat::<f64>::identity(kl, kl);
            for i in 0..s.nrows() {
                for a in 0..kl {
                    for b in 0..kl {
                        p[(a, b)] -= s[(i, c0 + a)] * s[(i, c0 + b)];
                    }
                }
            }
            let eig = p.self_adjoint_eigen(faer::Side::Lower).ok()?;
            let ev = eig.S().column_vector();
            let keep: Vec<usize> = (0..kl).filter(|&e| ev[e] > 0.5).collect();
            blocks.push(Mat::from_fn(kl, keep.len(), |a, b| eig.U()[(a, keep[b])]));
        }
        let n: usize = blocks.iter().map(|b| b.ncols()).sum();
        let mut reduce = Mat::<f64>::zeros(na, n);
        let mut o = 0;
        for (&(c0, _), b) in links.iter().zip(&blocks) {
            for j in 0..b.ncols() {
                for i in 0..b.nrows() {
                    reduce[(c0 + i, o + j)] = b[(i, j)];
                }
            }
            o += b.ncols();
        }
        Some(reduce)
    }
}

/// [`JointRows::coefficients`], compiled for the processor's vector instructions by pulp's
/// run-time dispatch (the sums `C_c + Σ_pq R_pq C_pq` of `r × 2k` entries each).
struct Coefficients<'a, 'b> {
    rows: &'a JointRows,
    xi: &'a Vector4<f64>,
    c: &'a mut [f64],
    dc: &'a mut [&'b mut [f64]; 4],
}

impl WithSimd for Coefficients<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let Coefficients { rows, xi, c, dc } = self;
        let (r, dr) = rotation_and_derivatives(xi);
        c.copy_from_slice(&rows.c_c);
        for d in dc.iter_mut() {
            d.fill(0.0);
        }
        for p in 0..3 {
            for q in 0..3 {
                let cpq = &rows.c_pq[3 * p + q];
                let w = r[(p, q)];
                c.iter_mut().zip(cpq).for_each(|(x, y)| *x += w * y);
                for (d, drd) in dc.iter_mut().zip(&dr) {
                    let w = drd[(p, q)];
                    if w != 0.0 {
                        d.iter_mut().zip(cpq).for_each(|(x, y)| *x += w * y);
                    }
                }
            }
        }
    }
}
