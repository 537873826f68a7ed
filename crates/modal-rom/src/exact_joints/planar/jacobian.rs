//! Exact Jacobian of the planar evaluation (theory.md §10.5, §10.9): the `(p, p2, u)` columns
//! as in [`crate::exact_joints::jacobian`] with the `−κΞ` term one rank-one term per joint, and
//! per joint the two in-plane quaternion columns `c ∈ {a, b}` with `A_c = ∂A/∂ξ_jc` (joint
//! `j`'s rows only), `V_c = A_cZ`, `Λ_c = Φ(−(W_jᵀV_c + V_cᵀW_j))`:
//!
//! ```text
//!   Z_c p   = −AᵀG(V_c p − A A_cᵀ W p) − A_cᵀ W p − Z Λ_cᵀ p
//!   Z_cᵀ f1 = −V_cᵀ G A f1 − Wᵀ A_c P f1 − Λ_c Zᵀ f1
//!   ∂V      = ∂Ȧ Z − ȦAᵀG V_c − (ȦA_cᵀ − ȦAᵀG A A_cᵀ) W − V Λ_cᵀ
//!   ∂W      = G V_c − G A A_cᵀ W − W Λ_cᵀ
//!   ∂Ȧ_i   = (δ_i Z_c p) A_iθ + [i = j] Δω_j ∂A_jθ/∂ξ_jc
//! ```
//!
//! (`∂A_θ/∂a = −2b A_1 + 2a A_2`, `∂A_θ/∂b = −2a A_1 − 2b A_2`); the out-of-plane columns
//! hold `U(ω_b) − Ū(ω_a)`'s columns in joint `j`'s rows only.

use super::eval::PlanarWs;
use super::Planar;
use crate::exact_joints::frame::{gemm, skew_apply, view, view_mut};
use nalgebra::Vector4;

/// `y = aᵀ x` (`a`: `x.len() × y.len()`, column-major).
fn mtv(y: &mut [f64], a: &[f64], x: &[f64]) {
    crate::exact_joints::frame::gemv_t(y, false, a, x.len(), x, 1.0);
}

impl Planar {
    /// The Jacobians into `jx` (`ns × ns`) and `ju` (`ns × nu`) after [`Planar::eval`]
    /// filled `ws`; `root`: the root quaternion's offset and rate.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn jacobian(
        &self,
        ws: &mut PlanarWs,
        x: &[f64],
        nu: usize,
        offsets: &[usize],
        root: Option<(usize, f64)>,
        jx: &mut [f64],
        ju: &mut [f64],
    ) {
        let (n, m, m2, r) = (self.n, self.m, self.m2, self.r);
        let nb = self.ops.w.ncols();
        let ns = ws.ns;
        jx.fill(0.0);
        ju.fill(0.0);
        let nf = n + nb;
        let jf = view(&ws.jf, nf, nf);
        let (z, zt) = (view(&ws.z, n, m), view(&ws.zt, m, n));
        gemm(view_mut(&mut ws.t11, m, n), false, zt, jf.submatrix(0, 0, n, n), 1.0);
        gemm(view_mut(jx, ns, ns).submatrix_mut(0, 0, m, m), false, view(&ws.t11, m, n), z, 1.0);
        gemm(view_mut(&mut ws.t12, m, nb), false, zt, jf.submatrix(0, n, n, nb), 1.0);
        let (j21, j22) = (jf.submatrix(n, 0, nb, n), jf.submatrix(n, n, nb, nb));
        if self.z2_identity {
            view_mut(jx, ns, ns).submatrix_mut(0, m, m, m2).copy_from(view(&ws.t12, m, nb));
            gemm(view_mut(jx, ns, ns).submatrix_mut(m, 0, m2, m), false, j21, z, 1.0);
            view_mut(jx, ns, ns).submatrix_mut(m, m, m2, m2).copy_from(j22);
        } else {
            let z2 = view(&self.z2, nb, m2);
            gemm(
                view_mut(jx, ns, ns).submatrix_mut(0, m, m, m2),
                false,
                view(&ws.t12, m, nb),
                z2,
                1.0,
            );
            gemm(view_mut(&mut ws.u21, m2, n), false, z2.transpose(), j21, 1.0);
            gemm(
                view_mut(jx, ns, ns).submatrix_mut(m, 0, m2, m),
                false,
                view(&ws.u21, m2, n),
                z,
                1.0,
            );
            gemm(view_mut(&mut ws.big, nb, m2), false, j22, z2, 1.0);
            gemm(
                view_mut(jx, ns, ns).submatrix_mut(m, m, m2, m2),
                false,
                z2.transpose(),
                view(&ws.big, nb, m2),
                1.0,
            );
        }
        // − K: K_il = M_li (i < l), −M_il (i > l), M = VᵀW
        gemm(
            view_mut(&mut ws.mm, m, m),
            false,
            view(&ws.v, r, m).transpose(),
            view(&ws.w, r, m),
            1.0,
        );
        for l in 0..m {
            let col = &mut jx[l * ns..l * ns + m];
            for i in 0..l {
                col[i] -= ws.mm[i * m + l];
            }
            for i in l + 1..m {
                col[i] += ws.mm[l * m + i];
            }
        }
        // Ξ (joint rows: ½ (δ_j Z)_k (−b, a n)) and −κΞ with κ_θj = K(V_θj, W_j) p
        let p = &x[..m];
        for (j, jr) in self.joints.iter().enumerate() {
            let (rj, o) = (jr.rows, jr.offset);
            let dz = &mut ws.dz[j * m..(j + 1) * m];
            mtv(dz, &ws.z[..n * m], &jr.delta);
            let [a, b] = ws.ab[j];
            let oj = offsets[j];
            for (k, &d) in dz.iter().enumerate() {
                jx[k * ns + oj] = -0.5 * b * d;
                jx[k * ns + oj + self.nu] = 0.5 * a * d;
            }
            for col in 0..m {
                for s in 0..rj {
                    ws.vc[col * rj + s] = ws.vth[col * r + o + s];
                    ws.v2c[col * rj + s] = ws.w[col * r + o + s];
                }
            }
            ws.kap.fill(0.0);
            skew_apply(&ws.vc, &ws.v2c, rj, p, &mut ws.kap, &mut ws.rtmp);
            for (k, &d) in dz.iter().enumerate() {
                let col = &mut jx[k * ns..k * ns + m];
                col.iter_mut().zip(&ws.kap).for_each(|(x, kp)| *x -= d * kp);
            }
            // out-of-plane columns: U(ω_b) − Ū(ω_a) in joint j's rows
            for c in (1..4).filter(|&c| c != self.nu) {
                for i in 0..4 {
                    jx[(oj + c) * ns + oj + i] = ws.mj[j][(i, c)];
                }
            }
        }
        if let (Some((o, w)), Some(t)) = (root, self.root.as_ref()) {
            let xr = Vector4::from_column_slice(&x[o..o + 4]);
            let u1 = self.u_n(1.0, false) * xr;
            let tz = &mut ws.lp;
            mtv(tz, &ws.z[..n * m], t);
            for (k, &d) in tz.iter().enumerate() {
                for i in 0..4 {
                    jx[k * ns + o + i] = d * u1[i];
                }
            }
            let ur = self.u_n(w, false);
            for c in 0..4 {
                for i in 0..4 {
                    jx[(o + c) * ns + o + i] = ur[(i, c)];
                }
            }
        }
        gemm(
            view_mut(ju, ns, nu).submatrix_mut(0, 0, m, nu),
            false,
            zt,
            self.ops.b_u.as_ref(),
            1.0,
        );
        if !self.joints.is_empty() {
            self.joint_columns(ws, x, offsets, root.map(|(o, _)| o), jx);
        }
    }
}
