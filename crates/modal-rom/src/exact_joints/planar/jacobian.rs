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
use crate::exact_joints::frame::{gemm, gemv, skew_apply, view, view_mut};
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

    /// The in-plane joint-quaternion columns (module docs).
    fn joint_columns(
        &self,
        ws: &mut PlanarWs,
        x: &[f64],
        offsets: &[usize],
        root: Option<usize>,
        jx: &mut [f64],
    ) {
        let (n, m, m2, r) = (self.n, self.m, self.m2, self.r);
        let nb = self.ops.w.ncols();
        let ns = ws.ns;
        let p = &x[..m];
        // A f1, G A f1, P f1, W p, Ȧ, ȦAᵀ, ȦAᵀG
        gemv(&mut ws.af1, false, &ws.a, r, &ws.f1, 1.0);
        gemv(&mut ws.gaf, false, &ws.g, r, &ws.af1, 1.0);
        ws.pf1.copy_from_slice(&ws.f1);
        crate::exact_joints::frame::gemv_t(&mut ws.pf1, true, &ws.a, r, &ws.gaf, -1.0);
        gemv(&mut ws.wp, false, &ws.w, r, p, 1.0);
        ws.adot[..r * n].fill(0.0);
        for (j, jr) in self.joints.iter().enumerate() {
            let [c, s, _] = ws.csr[j];
            let dw = ws.dw[j];
            let rj = jr.rows;
            for col in 0..n {
                for t in 0..rj {
                    ws.adot[col * r + jr.offset + t] =
                        dw * (-s * jr.a[1][col * rj + t] + c * jr.a[2][col * rj + t]);
                }
            }
        }
        let (av, adv) = (view(&ws.a, r, n), view(&ws.adot, r, n));
        gemm(view_mut(&mut ws.adat, r, r), false, adv, av.transpose(), 1.0);
        gemm(view_mut(&mut ws.adag, r, r), false, view(&ws.adat, r, r), view(&ws.g, r, r), 1.0);
        for (j, jr) in self.joints.iter().enumerate() {
            let (rj, o) = (jr.rows, jr.offset);
            let [a, b] = ws.ab[j];
            for ci in [0, self.nu] {
                let (dwc, d2) = if ci == 0 {
                    ([0.0, 2.0 * a, 2.0 * b, 2.0 * a], [-2.0 * b, 2.0 * a])
                } else {
                    ([0.0, -2.0 * b, 2.0 * a, 2.0 * b], [-2.0 * a, -2.0 * b])
                };
                // A_c (rows j), V_c = A_c Z, ∂A_θ/∂ξ_c Z
                ws.dc[..rj * n].fill(0.0);
                for al in 1..4 {
                    if al == 3 && jr.a3_zero {
                        continue;
                    }
                    let wgt = dwc[al];
                    ws.dc[..rj * n].iter_mut().zip(&jr.a[al]).for_each(|(d, s)| *d += wgt * s);
                }
                for col in 0..m {
                    for t in 0..rj {
                        let i = col * r + o + t;
                        let mut vc = dwc[1] * ws.az[0][i] + dwc[2] * ws.az[1][i];
                        if !jr.a3_zero {
                            vc += dwc[3] * ws.az[2][i];
                        }
                        ws.vc[col * rj + t] = vc;
                        ws.v2c[col * rj + t] = d2[0] * ws.az[0][i] + d2[1] * ws.az[1][i];
                    }
                }
                let wj = view(&ws.w, r, m).subrows(o, rj);
                // Λ = Φ(−(W_jᵀV_c + V_cᵀW_j))
                gemm(view_mut(&mut ws.mm, m, m), false, wj.transpose(), view(&ws.vc, rj, m), 1.0);
                for l in 0..m {
                    ws.lam[l * m + l] = -ws.mm[l * m + l];
                    for i in l + 1..m {
                        ws.lam[l * m + i] = -(ws.mm[l * m + i] + ws.mm[i * m + l]);
                    }
                }
                // Λᵀ p
                for l in 0..m {
                    ws.lp[l] = (l..m).map(|i| ws.lam[l * m + i] * p[i]).sum();
                }
                // A A_cᵀ, d = V_c p − A A_cᵀ (W p)_j, G d
                gemm(
                    view_mut(&mut ws.aac, r, rj),
                    false,
                    view(&ws.a, r, n),
                    view(&ws.dc, rj, n).transpose(),
                    1.0,
                );
                let wpj = &ws.wp[o..o + rj];
                gemv(&mut ws.dd, false, &ws.aac, r, wpj, -1.0);
                gemv(&mut ws.dd[o..o + rj], true, &ws.vc, rj, p, 1.0);
                gemv(&mut ws.gd, false, &ws.g, r, &ws.dd, 1.0);
                // Z_c p = −AᵀG d − A_cᵀ (W p)_j − Z Λᵀ p
                crate::exact_joints::frame::gemv_t(&mut ws.zcp, false, &ws.a, r, &ws.gd, -1.0);
                crate::exact_joints::frame::gemv_t(&mut ws.zcp, true, &ws.dc, rj, wpj, -1.0);
                gemv(&mut ws.zcp, true, &ws.z, n, &ws.lp, -1.0);
                // Z_cᵀ f1 + ZᵀJ11 Z_c p
                gemv(&mut ws.colp, false, &ws.t11, m, &ws.zcp, 1.0);
                crate::exact_joints::frame::gemv_t(
                    &mut ws.colp,
                    true,
                    &ws.vc,
                    rj,
                    &ws.gaf[o..o + rj],
                    -1.0,
                );
                gemv(&mut ws.dcp, false, &ws.dc, rj, &ws.pf1, 1.0);
                for (i, c) in ws.colp.iter_mut().enumerate() {
                    let wd: f64 = (0..rj).map(|t| ws.w[i * r + o + t] * ws.dcp[t]).sum();
                    let lz: f64 = (0..=i).map(|l| ws.lam[l * m + i] * ws.ztf[l]).sum();
                    *c -= wd + lz;
                }
                // p2 rows, ξ̇ rows, root rows
                let col = offsets[j] + ci;
                {
                    let u21 = if self.z2_identity {
                        view(&ws.jf, n + nb, n + nb).submatrix(n, 0, m2, n)
                    } else {
                        view(&ws.u21, m2, n)
                    };
                    gemm(view_mut(&mut ws.u2, m2, 1), false, u21, view(&ws.zcp, n, 1), 1.0);
                }
                jx[col * ns + m..col * ns + m + m2].copy_from_slice(&ws.u2[..m2]);
                for (i, ir) in self.joints.iter().enumerate() {
                    let d: f64 = ir.delta.iter().zip(&ws.zcp).map(|(a, b)| a * b).sum();
                    ws.ddw[i] = d;
                    let [ai, bi] = ws.ab[i];
                    let mut v = Vector4::zeros();
                    v[0] = -0.5 * bi * d;
                    v[self.nu] = 0.5 * ai * d;
                    if i == j {
                        v += ws.mj[j].column(ci);
                    }
                    let oi = offsets[i];
                    jx[col * ns + oi..col * ns + oi + 4].copy_from_slice(v.as_slice());
                }
                if let (Some(or), Some(t)) = (root, self.root.as_ref()) {
                    let d: f64 = t.iter().zip(&ws.zcp).map(|(a, b)| a * b).sum();
                    let v = self.u_n(d, false) * Vector4::from_column_slice(&x[or..or + 4]);
                    jx[col * ns + or..col * ns + or + 4].copy_from_slice(v.as_slice());
                }
                // ∂V = ∂ȦZ − ȦAᵀG V_c − X1 W_j − V Λᵀ, X1 = ȦA_cᵀ − ȦAᵀG A A_cᵀ
                for (i, ir) in self.joints.iter().enumerate() {
                    let d = ws.ddw[i];
                    for c in 0..m {
                        for t in ir.offset..ir.offset + ir.rows {
                            ws.dv[c * r + t] = d * ws.vth[c * r + t];
                        }
                    }
                }
                let dw = ws.dw[j];
                for c in 0..m {
                    for t in 0..rj {
                        ws.dv[c * r + o + t] += dw * ws.v2c[c * rj + t];
                    }
                }
                gemm(
                    view_mut(&mut ws.dv, r, m),
                    true,
                    view(&ws.adag, r, r).subcols(o, rj),
                    view(&ws.vc, rj, m),
                    -1.0,
                );
                gemm(
                    view_mut(&mut ws.x1, r, rj),
                    false,
                    view(&ws.adot, r, n),
                    view(&ws.dc, rj, n).transpose(),
                    1.0,
                );
                gemm(
                    view_mut(&mut ws.x1, r, rj),
                    true,
                    view(&ws.adag, r, r),
                    view(&ws.aac, r, rj),
                    -1.0,
                );
                gemm(view_mut(&mut ws.dv, r, m), true, view(&ws.x1, r, rj), wj, -1.0);
                // ∂W = G V_c − G A A_cᵀ W_j − W Λᵀ
                gemm(
                    view_mut(&mut ws.gaac, r, rj),
                    false,
                    view(&ws.g, r, r),
                    view(&ws.aac, r, rj),
                    1.0,
                );
                gemm(
                    view_mut(&mut ws.dwm, r, m),
                    false,
                    view(&ws.g, r, r).subcols(o, rj),
                    view(&ws.vc, rj, m),
                    1.0,
                );
                gemm(view_mut(&mut ws.dwm, r, m), true, view(&ws.gaac, r, rj), wj, -1.0);
                // − V Λᵀ, − W Λᵀ: column i gets Σ_{l ≤ i} Λ_il (V, W)_l
                for i in 0..m {
                    for l in 0..=i {
                        let lam = ws.lam[l * m + i];
                        for t in 0..r {
                            ws.dv[i * r + t] -= lam * ws.v[l * r + t];
                            ws.dwm[i * r + t] -= lam * ws.w[l * r + t];
                        }
                    }
                }
                ws.dkp.fill(0.0);
                skew_apply(&ws.dv, &ws.w, r, p, &mut ws.dkp, &mut ws.rtmp);
                skew_apply(&ws.v, &ws.dwm, r, p, &mut ws.dkp, &mut ws.rtmp);
                for i in 0..m {
                    jx[col * ns + i] = ws.colp[i] - ws.dkp[i];
                }
            }
        }
    }
}
