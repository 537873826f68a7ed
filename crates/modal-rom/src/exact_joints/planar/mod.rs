//! The planar evaluation of the exact-joints model (theory.md §10.9): the same right-hand side
//! and exact Jacobian as the general evaluation ([`super::eval`], [`super::jacobian`]), for a
//! planar model at a planar state, with the structure the plane gives.
//!
//! A model is planar when its layout has the three in-plane components (two velocities, the
//! rate about the plane's normal `n`) and every joint's rows depend on `R(ξ_j)` only through
//! its in-plane block and `R_nn` (no mixed `R_pn`). A state is planar when every joint
//! quaternion is `ξ_j = (a_j, b_j n)` (its out-of-plane components exactly zero); the evaluation
//! runs at unit joint quaternions ([`super::unit_rotation`]), where `R(ξ_j) = c I_plane + s ñ +
//! ρ n nᵀ` with `c = a² − b²`, `s = 2ab`, `ρ = a² + b²` (eq. 9 in its homogeneous form). Then:
//!
//! * the model's fields are already reduced by the support rows (theory.md §10.3), so only
//!   the joint rows remain;
//! * each joint's rows are `A_j = A_j0 + c A_j1 + s A_j2 + ρ A_j3` with four constant
//!   matrices on the reduced fields, `Ȧ_j = Δω_j A_jθ` (`A_jθ = −s A_j1 + c A_j2`,
//!   `Δω_j = ω_b − ω_a`), and `ξ̇_j = ½Δω_j (−b, a n)`;
//! * the Jacobian's `ξ_j` columns move only along `a` and `b`, and only the tangent
//!   `t = (−b, a)` is needed (the columns are `∂f/∂x̂ Π`, [`super::unit_rotation`]): one column
//!   `g`, written as `g tᵀ`; the out-of-plane columns hold
//!   `ξ̇_j`'s own dependence on `ξ_j` (`∂A/∂ξ_jc = 0`, `∂²A/∂ξ_jc∂ξ_jd = 0` for the in-plane
//!   `d`), and the `−κΞ` term of the `p` columns is one rank-one term per joint,
//!   `(δ_j Z)ᵀ ⊗ K(A_jθ Z, W_j) p` (`δ_j` the rows of `Δω_j`).

mod columns;
mod eval;
mod jacobian;
mod kernels;
#[cfg(test)]
mod tests;

pub(crate) use eval::with_planar_workspace;

use crate::exact_joints::ambient::{AmbientOps, LinkBasis};
use crate::exact_joints::rows::Constraints;
use faer::Mat;
use intrinsic_beam::operators::tilde;
use nalgebra::Vector3;

/// One joint's constant pieces on the reduced fields.
#[derive(Clone, Debug)]
pub(crate) struct PlanarJoint {
    /// Rows `r_j`, first row in `A`.
    rows: usize,
    offset: usize,
    /// `A_jα` (`r_j × n`, column-major), `α = 0…3` (module docs).
    a: [Vec<f64>; 4],
    /// The same row by row (`r_j` rows of `n`, each contiguous).
    at: [Vec<f64>; 4],
    /// `A_jα Ẑ0` (`r_j × m`), set with the coordinates.
    az0: [Vec<f64>; 4],
    /// `A_jα A_iβᵀ` for `α = 1…3`, `β = 0…3` over the rows `i` of all joints: entry
    /// `((α − 1)·4 + β)·r_j·r + t·r + i` is `A_jα[t, ·] · A_{k(i)β}[i, ·]` (`k(i)` the joint of
    /// row `i`), so that `A A_αᵀ` and `Ȧ A_αᵀ` are combinations of constants (theory.md §10.9).
    pa: Vec<f64>,
    /// `A_jα C` (`r_j × k`) for the columns `C` of [`Planar::zcon`].
    acon: [Vec<f64>; 4],
    /// Whether `A_j3 = 0`.
    a3_zero: bool,
    /// Rows of `ω_a`, `ω_b` (`n` each).
    wa: Vec<f64>,
    wb: Vec<f64>,
    /// `δ_j = ω_b − ω_a` rows (`n`).
    delta: Vec<f64>,
}

/// The planar evaluation's constants (module docs).
#[derive(Clone, Debug)]
pub(crate) struct Planar {
    /// Quaternion index of the normal's component (`1 + axis`).
    nu: usize,
    /// Fields `n`.
    n: usize,
    /// Force fields `nb`, the ambient operators' scratch length and layout key (the
    /// operators themselves are the model's, passed to [`Planar::eval`]).
    nb: usize,
    amb_len: usize,
    amb_key: Vec<usize>,
    joints: Vec<PlanarJoint>,
    /// Total joint rows.
    r: usize,
    /// Root node's rate row (`n`) when the root is carried.
    root: Option<Vec<f64>>,
    /// The constant vectors `C` the Jacobian multiplies by `Zᵀ` (`n × k`, column-major): the
    /// joints' `δ_j`, the root's rate row, the input columns `B_u`; `k`, and `Ẑ0ᵀC` row by
    /// row (`m × k`, set with the coordinates).
    zcon: Vec<f64>,
    kc: usize,
    z0con: Vec<f64>,
    /// `Ẑ0 = NᵀZ0` (`n × m`), `Z2` (`nb × m2`), column-major.
    z0: Vec<f64>,
    z2: Vec<f64>,
    z2_identity: bool,
    m: usize,
    m2: usize,
    /// The workspace sizes ([`Planar::dims_key`]), the joint quaternions' offsets in the state
    /// and the root quaternion's.
    key: Vec<usize>,
    offsets: Vec<usize>,
    root_offset: Option<usize>,
}

/// Column-major entries of `m`.
fn flat(m: &Mat<f64>) -> Vec<f64> {
    (0..m.ncols()).flat_map(|j| (0..m.nrows()).map(move |i| m[(i, j)])).collect()
}

impl Planar {
    /// The planar constants of a model on link fields `basis` with rows `cons` and rotational
    /// components `rate_comps`, or `None` when the model is not planar (module docs).
    pub(crate) fn new(
        basis: &LinkBasis,
        cons: &Constraints,
        rate_comps: &[(usize, usize)],
        ops: &AmbientOps,
    ) -> Option<Self> {
        let layout = &basis.layout;
        let k = layout.k();
        if k != 3 || rate_comps.len() != 1 {
            return None;
        }
        let (rate_c, axis) = rate_comps[0];
        let na = basis.n1();
        // rows of joints: no mixed R_pn coefficient
        // (a joint's running sums are local arrays of up to six rows)
        if cons.joints.iter().any(|j| j.rows > 6) {
            return None;
        }
        for j in &cons.joints {
            for p in 0..3 {
                for q in 0..3 {
                    if (p == axis) != (q == axis) && j.c_pq[3 * p + q].iter().any(|&v| v != 0.0) {
                        return None;
                    }
                }
            }
        }
        // the model's fields are reduced by its support rows wherever they are each on one
        // link (`ExactJointsRom::new`): only the joint rows remain
        if cons.support.nrows() != 0 {
            return None;
        }
        let n = na;
        let nt = tilde(&Vector3::ith(axis, 1.0));
        let mut joints = Vec::new();
        let mut r = 0;
        for j in &cons.joints {
            let en = &j.e;
            let (rj, kk) = (j.rows, j.e.nrows());
            let cm = |c: &[f64]| Mat::from_fn(rj, kk, |i, col| c[col * rj + i]);
            let mut c1 = vec![0.0; rj * kk];
            let mut c2 = vec![0.0; rj * kk];
            for p in (0..3).filter(|&p| p != axis) {
                for q in (0..3).filter(|&q| q != axis) {
                    let cpq = &j.c_pq[3 * p + q];
                    if p == q {
                        c1.iter_mut().zip(cpq).for_each(|(x, y)| *x += y);
                    }
                    let w = nt[(p, q)];
                    c2.iter_mut().zip(cpq).for_each(|(x, y)| *x += w * y);
                }
            }
            let c3 = &j.c_pq[4 * axis];
            let a = [&j.c_c[..], &c1[..], &c2[..], &c3[..]].map(|c| flat(&(cm(c) * en)));
            let a3_zero = a[3].iter().all(|&v| v == 0.0);
            let at = std::array::from_fn(|al| {
                (0..rj)
                    .flat_map(|t| (0..n).map(move |c| (t, c)))
                    .map(|(t, c)| a[al][c * rj + t])
                    .collect()
            });
            let row = |i: usize| -> Vec<f64> { (0..n).map(|c| en[(i, c)]).collect() };
            let (wa, wb) = (row(rate_c), row(k + rate_c));
            let delta = wb.iter().zip(&wa).map(|(b, a)| b - a).collect();
            joints.push(PlanarJoint {
                rows: rj,
                offset: r,
                a,
                at,
                az0: Default::default(),
                pa: Vec::new(),
                acon: Default::default(),
                a3_zero,
                wa,
                wb,
                delta,
            });
            r += rj;
        }
        for j in 0..joints.len() {
            let rj = joints[j].rows;
            let mut pa = vec![0.0; 12 * rj * r];
            for al in 0..3 {
                for be in 0..4 {
                    for t in 0..rj {
                        let x = &joints[j].at[al + 1][t * n..(t + 1) * n];
                        for k in &joints {
                            for il in 0..k.rows {
                                let y = &k.at[be][il * n..(il + 1) * n];
                                let d = x.iter().zip(y).map(|(a, b)| a * b).sum();
                                pa[((al * 4 + be) * rj + t) * r + k.offset + il] = d;
                            }
                        }
                    }
                }
            }
            joints[j].pa = pa;
        }
        let root = cons.root.map(|(b, nd, _)| {
            let i = layout.x1_index(b, nd, rate_c);
            (0..n).map(|c| basis.phi1[(i, c)]).collect()
        });
        let mut zcon: Vec<f64> = joints.iter().flat_map(|j| j.delta.iter().copied()).collect();
        zcon.extend(root.iter().flatten());
        zcon.extend((0..ops.b_u.ncols()).flat_map(|k| ops.b_u.col_as_slice(k).iter().copied()));
        let kc = zcon.len() / n.max(1);
        for j in &mut joints {
            let rj = j.rows;
            j.acon = std::array::from_fn(|al| {
                let mut v = vec![0.0; rj * kc];
                for k in 0..kc {
                    for t in 0..rj {
                        let row = &j.at[al][t * n..(t + 1) * n];
                        v[k * rj + t] =
                            row.iter().zip(&zcon[k * n..(k + 1) * n]).map(|(a, b)| a * b).sum();
                    }
                }
                v
            });
        }
        Some(Planar {
            nu: 1 + axis,
            zcon,
            kc,
            z0con: Vec::new(),
            n,
            nb: ops.w.ncols(),
            amb_len: ops.scratch_len(),
            amb_key: ops.layout_key().collect(),
            joints,
            r,
            root,
            z0: Vec::new(),
            z2: Vec::new(),
            z2_identity: false,
            m: 0,
            m2: 0,
            key: Vec::new(),
            offsets: Vec::new(),
            root_offset: None,
        })
    }

    /// Sets the reduced coordinates `Z0` (`na × m`, `S Z0 = 0`) and `Z2`.
    pub(crate) fn set_coordinates(&mut self, z0: &Mat<f64>, z2: &Mat<f64>, z2_identity: bool) {
        self.m = z0.ncols();
        self.m2 = z2.ncols();
        self.z0 = flat(z0);
        self.z2 = flat(z2);
        self.z2_identity = z2_identity;
        let root = usize::from(self.root.is_some());
        self.root_offset = self.root.is_some().then_some(self.m + self.m2);
        self.offsets = (0..self.joints.len()).map(|j| self.m + self.m2 + 4 * (root + j)).collect();
        let n = self.n;
        for j in &mut self.joints {
            let rj = j.rows;
            for (az, a) in j.az0.iter_mut().zip(&j.a) {
                let am = Mat::from_fn(rj, n, |i, c| a[c * rj + i]);
                *az = flat(&(am * z0));
            }
        }
        let kc = self.kc;
        self.z0con = (0..self.m)
            .flat_map(|i| (0..kc).map(move |k| (i, k)))
            .map(|(i, k)| {
                let col = &self.z0[i * n..(i + 1) * n];
                col.iter().zip(&self.zcon[k * n..(k + 1) * n]).map(|(a, b)| a * b).sum()
            })
            .collect();
        self.key = self.dims_key();
    }

    /// Whether the joint quaternions of `x` (at `offsets`) are planar (module docs).
    pub(crate) fn accepts(&self, x: &[f64], offsets: impl Iterator<Item = usize>) -> bool {
        let nu = self.nu;
        offsets.into_iter().all(|o| (1..4).all(|c| c == nu || x[o + c] == 0.0))
    }
}

impl crate::exact_joints::ExactJointsRom {
    /// The planar evaluation of `(x, u)` into `f` (and the Jacobians), or `None` when the model
    /// or the state is not planar (module docs); the state and input are checked by the caller.
    pub(crate) fn planar_eval(
        &self,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jac: Option<(&mut [f64], &mut [f64])>,
    ) -> Option<crate::error::Result<()>> {
        let pl = self.planar.as_deref()?;
        if !pl.accepts(x, pl.offsets.iter().copied()) {
            return None;
        }
        let (offsets, root) = (&pl.offsets[..], pl.root_offset);
        debug_assert!(offsets.iter().enumerate().all(|(j, &o)| o == self.joint_offset(j)));
        debug_assert_eq!(root, self.has_root().then(|| self.root_offset()));
        Some(with_planar_workspace(pl, |ws| pl.eval(&self.ops, ws, x, u, offsets, root, f, jac)))
    }

    /// The general evaluation (also for planar models): right-hand side and, with `jac`, the
    /// exact Jacobians, at any joint quaternion norm.
    #[cfg(test)]
    pub(crate) fn eval_general(
        &self,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jac: Option<(&mut [f64], &mut [f64])>,
    ) -> crate::error::Result<()> {
        self.evaluate(x, u, f, jac, false)
    }

    /// Whether the planar evaluation is available for this model.
    #[cfg(test)]
    pub(crate) fn is_planar(&self) -> bool {
        self.planar.is_some()
    }
}
