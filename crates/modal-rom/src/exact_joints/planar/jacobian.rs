//! Exact Jacobian of the planar evaluation (theory.md §10.5, §10.9): the `(p, p2, u)` columns
//! as in [`crate::exact_joints::jacobian`] with the `−κΞ` term one rank-one term per joint, and
//! per joint the in-plane quaternion columns from the one derivative `g` along the tangent
//! `c = t = (−b, a)` (written `g tᵀ`) with `A_c = ∂A/∂t` (joint `j`'s rows only), `V_c = A_cZ`,
//! `Λ_c = Φ(−(W_jᵀV_c + V_cᵀW_j))`:
//!
//! ```text
//!   Z_c p   = −AᵀG(V_c p − A A_cᵀ W p) − A_cᵀ W p − Z Λ_cᵀ p
//!   Z_cᵀ f1 = −V_cᵀ G A f1 − Wᵀ A_c P f1 − Λ_c Zᵀ f1
//!   ∂V      = ∂Ȧ Z − ȦAᵀG V_c − (ȦA_cᵀ − ȦAᵀG A A_cᵀ) W − V Λ_cᵀ
//!   ∂W      = G V_c − G A A_cᵀ W − W Λ_cᵀ
//!   ∂Ȧ_i   = (δ_i Z_c p) A_iθ + [i = j] Δω_j ∂A_jθ/∂t
//! ```
//!
//! (`∂A/∂t = −4ab A_1 + 2(a² − b²) A_2`, `∂A_θ/∂t = −2(a² − b²) A_1 − 4ab A_2`); the
//! out-of-plane columns hold `U(ω_b) − Ū(ω_a)`'s columns in joint `j`'s rows only.

use super::eval::PlanarWs;
use super::Planar;
use crate::exact_joints::frame::{matmul_nn, matmul_tn, skew_apply};
use nalgebra::Vector4;

impl Planar {
    /// The Jacobians into `jx` (`ns × ns`) and `ju` (`ns × nu`) after [`Planar::eval`]
    /// filled `ws`; `root`: the root quaternion's offset and rate; `R > 0`: one joint of `R`
    /// rows (chosen once by [`Planar::eval`]).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(super) fn jacobian<const R: usize>(
        &self,
        ws: &mut PlanarWs,
        x: &[f64],
        nu: usize,
        offsets: &[usize],
        root: Option<(usize, f64)>,
        jx: &mut [f64],
        ju: &mut [f64],
    ) {
        let (n, m, m2) = (self.n, self.m, self.m2);
        let r = if R > 0 { R } else { self.r };
        let nb = self.nb;
        let ns = ws.ns;
        jx.fill(0.0);
        ju.fill(0.0);
        let nf = n + nb;
        // [J11 J12; J21 J22] blockdiag(Z, Z2) (`T`, nf rows), then Zᵀ T's upper rows and
        // Z2ᵀ T's lower rows; with `Z2 = I` the lower rows and `J`'s own columns as they are
        let zm = &ws.z[..n * m];
        let zt = &ws.zt[..m * n];
        let t = &mut ws.tzm[..nf * m];
        matmul_nn(t, nf, &ws.jf[..nf * n], nf, zm, n, n, m);
        matmul_nn(jx, ns, zt, m, t, nf, n, m);
        if self.z2_identity {
            for k in 0..m {
                jx[k * ns + m..k * ns + m + m2].copy_from_slice(&t[k * nf + n..(k + 1) * nf]);
            }
            matmul_nn(&mut jx[m * ns..], ns, zt, m, &ws.jf[n * nf..], nf, n, m2);
            for k in 0..m2 {
                let src = &ws.jf[(n + k) * nf + n..(n + k + 1) * nf];
                jx[(m + k) * ns + m..(m + k) * ns + m + m2].copy_from_slice(src);
            }
        } else {
            let z2 = &self.z2[..nb * m2];
            matmul_tn(&mut jx[m..], ns, z2, nb, &t[n..], nf, m);
            let t2 = &mut ws.tzm[..nf * m2];
            matmul_nn(t2, nf, &ws.jf[n * nf..nf * nf], nf, z2, nb, nb, m2);
            matmul_nn(&mut jx[m * ns..], ns, zt, m, t2, nf, n, m2);
            matmul_tn(&mut jx[m * ns + m..], ns, z2, nb, &t2[n..], nf, m2);
        }
        // − K: K_il = M_li (i < l), −M_il (i > l), M = VᵀW
        for l in 0..m {
            let (vl, wl) = (&ws.v[l * r..(l + 1) * r], &ws.w[l * r..(l + 1) * r]);
            let col = &mut jx[l * ns..l * ns + m];
            for (i, c) in col[..l].iter_mut().enumerate() {
                let wi = &ws.w[i * r..(i + 1) * r];
                *c -= (0..r).map(|t| vl[t] * wi[t]).sum::<f64>();
            }
            for (i, c) in col.iter_mut().enumerate().skip(l + 1) {
                let vi = &ws.v[i * r..(i + 1) * r];
                *c += (0..r).map(|t| vi[t] * wl[t]).sum::<f64>();
            }
        }
        // Zᵀ δ_j, Zᵀ (root rate row), Zᵀ B_u: the frame's `ztc` (row by row, `kc` per row)
        let kc = self.kc;
        // Ξ (joint rows: ½ (δ_j Z)_k (−b, a n)) and −κΞ with κ_θj = K(V_θj, W_j) p
        let p = &x[..m];
        for (j, jr) in self.joints.iter().enumerate() {
            let (rj, o) = (jr.rows, jr.offset);
            let dz = &mut ws.lp[..m];
            dz.iter_mut().enumerate().for_each(|(i, d)| *d = ws.ztc[i * kc + j]);
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
        if let (Some((o, w)), Some(_)) = (root, self.root.as_ref()) {
            let xr = Vector4::from_column_slice(&x[o..o + 4]);
            let u1 = self.u_n(1.0, false) * xr;
            let nj = self.joints.len();
            for k in 0..m {
                let d = ws.ztc[k * kc + nj];
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
        let o = self.joints.len() + usize::from(self.root.is_some());
        for k in 0..nu {
            for i in 0..m {
                ju[k * ns + i] = ws.ztc[i * kc + o + k];
            }
        }
        if !self.joints.is_empty() {
            self.joint_columns(ws, x, offsets, root.map(|(o, _)| o), jx);
        }
    }
}
