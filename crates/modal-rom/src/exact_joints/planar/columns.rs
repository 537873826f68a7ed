//! The in-plane joint-quaternion columns of the planar Jacobian (formulas in
//! [`super::jacobian`]): per joint, the pieces linear in `A_α` (`A A_αᵀ`, `Ȧ A_αᵀ`, `A_α P f1`,
//! `A_αᵀ (W p)_j`, `α = 1, 2`), combined with `∂w_α/∂t` (`w = (1, c, s, ρ)`) into the one column
//! along the tangent `t`;
//! `Λ_c` (`m × m`, rank `2r_j`) applied by running sums of its generators, never formed; and
//! `∂(Kp) = K(∂V, W)p + K(V, ∂W)p` as one skew application on the stacked `[∂V; V]`, `[W; ∂W]`
//! (`K` is bilinear in its row sums).

use super::eval::PlanarWs;
use super::kernels::gemv_small;
use super::Planar;
use crate::exact_joints::frame::{gemv, gemv_t, matmul_nn, skew_apply};
use nalgebra::Vector4;

impl Planar {
    /// The in-plane joint-quaternion columns into `jx` (module docs).
    pub(super) fn joint_columns(
        &self,
        ws: &mut PlanarWs,
        x: &[f64],
        offsets: &[usize],
        root: Option<usize>,
        jx: &mut [f64],
    ) {
        // one revolute joint (two rows): row counts known at compile time
        if self.r == 2 && self.joints.len() == 1 {
            self.joint_columns_imp::<2>(ws, x, offsets, root, jx)
        } else {
            self.joint_columns_imp::<0>(ws, x, offsets, root, jx)
        }
    }

    /// [`Planar::joint_columns`]; `R > 0`: one joint of `R` rows.
    #[inline(always)]
    fn joint_columns_imp<const R: usize>(
        &self,
        ws: &mut PlanarWs,
        x: &[f64],
        offsets: &[usize],
        root: Option<usize>,
        jx: &mut [f64],
    ) {
        let (n, m, m2) = (self.n, self.m, self.m2);
        let r = if R > 0 { R } else { self.r };
        let nb = self.nb;
        let nf = n + nb;
        let ns = ws.ns;
        let r2 = 2 * r;
        let p = &x[..m];
        // A f1, G A f1, P f1, W p, Ȧ, ȦAᵀ, ȦAᵀG
        gemv_small(&mut ws.af1, false, &ws.a, r, &ws.f1, 1.0);
        gemv_small(&mut ws.gaf, false, &ws.g, r, &ws.af1, 1.0);
        ws.pf1.copy_from_slice(&ws.f1);
        gemv_t(&mut ws.pf1, true, &ws.a, r, &ws.gaf, -1.0);
        gemv_small(&mut ws.wp, false, &ws.w, r, p, 1.0);
        // ȦAᵀ (rows of each joint: only its own Ȧ rows are non-zero): Ȧ_j = Δω_j (−s A_j1 +
        // c A_j2), so its rows are combinations of the frame's A_jα Aᵀ
        for (j, jr) in self.joints.iter().enumerate() {
            let [c, s, _] = ws.csr[j];
            let dw = ws.dw[j];
            let (rj, o) = (jr.rows, jr.offset);
            let paa = &ws.paa[3 * r * o..3 * r * (o + rj)];
            for t in 0..rj {
                let (p1, p2) = (&paa[t * r..(t + 1) * r], &paa[(rj + t) * r..(rj + t + 1) * r]);
                for col in 0..r {
                    ws.adat[col * r + o + t] = dw * (-s * p1[col] + c * p2[col]);
                }
            }
        }
        for col in 0..r {
            for i in 0..r {
                ws.adag[col * r + i] = (0..r).map(|k| ws.adat[k * r + i] * ws.g[col * r + k]).sum();
            }
        }
        // the stacked halves that do not change with the column: V (rows r..2r of sa), W
        // (rows 0..r of sb)
        for i in 0..m {
            ws.sa[i * r2 + r..(i + 1) * r2].copy_from_slice(&ws.v[i * r..(i + 1) * r]);
            ws.sb[i * r2..i * r2 + r].copy_from_slice(&ws.w[i * r..(i + 1) * r]);
        }
        for (j, jr) in self.joints.iter().enumerate() {
            let (rj, o) = if R > 0 { (R, 0) } else { (jr.rows, jr.offset) };
            let [a, b] = ws.ab[j];
            // along the tangent (−b, a) `∂ρ = 0`: A_3 drops out
            let alphas = 2;
            // per α: Ȧ A_αᵀ (r × r_j) from the constants A_jα A_kβᵀ, A_α P f1 (r_j),
            // A_αᵀ (W p)_j (n); A A_αᵀ is the frame's
            let aa = &ws.paa[3 * r * o..3 * r * (o + rj)];
            for al in 0..alphas {
                let aal = &jr.a[al + 1];
                for t in 0..rj {
                    for (k, kr) in self.joints.iter().enumerate() {
                        let [c, s, _] = ws.csr[k];
                        let dw = ws.dw[k];
                        for i in kr.offset..kr.offset + kr.rows {
                            let e = |be: usize| jr.pa[((al * 4 + be) * rj + t) * r + i];
                            ws.ada[(al * rj + t) * r + i] = dw * (-s * e(1) + c * e(2));
                        }
                    }
                }
                gemv_small(&mut ws.apf[al * rj..(al + 1) * rj], false, aal, rj, &ws.pf1, 1.0);
                gemv_t(&mut ws.atw[al * n..(al + 1) * n], false, aal, rj, &ws.wp[o..o + rj], 1.0);
            }
            {
                // the derivative along t = (−b, a): ∂w_α/∂ξ (w = (c, s, ρ)) and ∂A_θ/∂ξ
                // (module docs) combined, `−b ∂_a + a ∂_b`
                let dwc = [-4.0 * a * b, 2.0 * (a * a - b * b)];
                let d2 = [2.0 * (b * b - a * a), -4.0 * a * b];
                let comb = |v: &[f64], len: usize, out: &mut [f64]| {
                    for (e, y) in out[..len].iter_mut().enumerate() {
                        *y = (0..alphas).map(|al| dwc[al] * v[al * len + e]).sum();
                    }
                };
                // A A_cᵀ, Ȧ A_cᵀ (r × r_j), A_c P f1 (r_j)
                comb(aa, r * rj, &mut ws.aac);
                comb(&ws.ada, r * rj, &mut ws.x1);
                comb(&ws.apf, rj, &mut ws.dcp);
                // V_c = A_c Z, ∂A_θ/∂ξ_c Z (r_j × m)
                for col in 0..m {
                    for t in 0..rj {
                        let i = col * r + o + t;
                        ws.vc[col * rj + t] = dwc[0] * ws.az[0][i] + dwc[1] * ws.az[1][i];
                        ws.v2c[col * rj + t] = d2[0] * ws.az[0][i] + d2[1] * ws.az[1][i];
                    }
                }
                // Λ = Φ(−(W_jᵀV_c + V_cᵀW_j)) is never formed: Λ_il = −(w_i·v_l + w_l·v_i)
                // (i > l), −w_l·v_l (i = l) with w_l, v_l the columns of W_j, V_c, so Λᵀp and
                // Λy take suffix and prefix sums of p_i w_i, p_i v_i (r_j entries each);
                // Λᵀp: lp_l = −v_l·Σ_{i>l} p_i w_i − w_l·Σ_{i>l} p_i v_i − p_l w_l·v_l
                let (mut sw, mut sv) = ([0.0f64; 6], [0.0f64; 6]);
                let (sw, sv) = (&mut sw[..rj], &mut sv[..rj]);
                for l in (0..m).rev() {
                    let (wl, vl) = (&ws.w[l * r + o..l * r + o + rj], &ws.vc[l * rj..(l + 1) * rj]);
                    let mut d = 0.0;
                    for t in 0..rj {
                        d += vl[t] * sw[t] + wl[t] * sv[t] + p[l] * (wl[t] * vl[t]);
                    }
                    ws.lp[l] = -d;
                    for t in 0..rj {
                        sw[t] += p[l] * wl[t];
                        sv[t] += p[l] * vl[t];
                    }
                }
                // d = V_c p − A A_cᵀ (W p)_j, G d
                let wpj = &ws.wp[o..o + rj];
                gemv_small(&mut ws.dd, false, &ws.aac, r, wpj, -1.0);
                gemv_small(&mut ws.dd[o..o + rj], true, &ws.vc, rj, p, 1.0);
                gemv_small(&mut ws.gd, false, &ws.g, r, &ws.dd, 1.0);
                // Z_c p = −AᵀG d − A_cᵀ (W p)_j − Z Λᵀ p
                gemv_t(&mut ws.zcp, false, &ws.a, r, &ws.gd, -1.0);
                for al in 0..alphas {
                    let wgt = dwc[al];
                    let src = &ws.atw[al * n..(al + 1) * n];
                    ws.zcp.iter_mut().zip(src).for_each(|(z, s)| *z -= wgt * s);
                }
                gemv(&mut ws.zcp, true, &ws.z, n, &ws.lp, -1.0);
                // Z_cᵀ f1 + ZᵀJ11 Z_c p = ZᵀJ11 Z_c p − V_cᵀ(GAf1)_j − W_jᵀ A_c P f1 − Λ Zᵀf1
                // (J11 Z_c p; J21 Z_c p) by `matmul_nn`, then Zᵀ of the upper rows
                matmul_nn(&mut ws.tz, nf, &ws.jf[..nf * n], nf, &ws.zcp, n, n, 1);
                gemv_t(&mut ws.colp, false, &ws.z[..n * m], n, &ws.tz[..n], 1.0);
                // (Λ Zᵀf1 by prefix sums: (Λy)_i = −w_i·Σ_{l<i} y_l v_l − v_i·Σ_{l<i} y_l w_l
                // − y_i w_i·v_i)
                let (mut sw, mut sv) = ([0.0f64; 6], [0.0f64; 6]);
                let (sw, sv) = (&mut sw[..rj], &mut sv[..rj]);
                for (i, &y) in ws.ztf.iter().enumerate() {
                    let (wi, vi) = (&ws.w[i * r + o..i * r + o + rj], &ws.vc[i * rj..(i + 1) * rj]);
                    let mut d = 0.0;
                    for t in 0..rj {
                        d += wi[t] * sv[t] + vi[t] * sw[t] + y * (wi[t] * vi[t]);
                    }
                    ws.colp[i] += d;
                    for t in 0..rj {
                        sw[t] += y * wi[t];
                        sv[t] += y * vi[t];
                    }
                }
                let (gaf, dcp) = (&ws.gaf[o..o + rj], &ws.dcp[..rj]);
                for (i, c) in ws.colp.iter_mut().enumerate() {
                    let (vi, wi) = (&ws.vc[i * rj..(i + 1) * rj], &ws.w[i * r + o..i * r + o + rj]);
                    *c -= (0..rj).map(|t| vi[t] * gaf[t] + wi[t] * dcp[t]).sum::<f64>();
                }
                // p2 rows (Z2ᵀJ21 Z_c p), ξ̇ rows, root rows
                let col = offsets[j];
                let jc = &mut jx[col * ns..(col + 1) * ns];
                if self.z2_identity {
                    jc[m..m + m2].copy_from_slice(&ws.tz[n..nf]);
                } else {
                    gemv_t(&mut jc[m..m + m2], false, &self.z2, nb, &ws.tz[n..nf], 1.0);
                }
                for (i, ir) in self.joints.iter().enumerate() {
                    let d: f64 = ir.delta.iter().zip(&ws.zcp).map(|(a, b)| a * b).sum();
                    ws.ddw[i] = d;
                    let [ai, bi] = ws.ab[i];
                    let mut v = Vector4::zeros();
                    v[0] = -0.5 * bi * d;
                    v[self.nu] = 0.5 * ai * d;
                    if i == j {
                        v += ws.mj[j].column(0) * -b + ws.mj[j].column(self.nu) * a;
                    }
                    let oi = offsets[i];
                    jc[oi..oi + 4].copy_from_slice(v.as_slice());
                }
                if let (Some(or), Some(t)) = (root, self.root.as_ref()) {
                    let d: f64 = t.iter().zip(&ws.zcp).map(|(a, b)| a * b).sum();
                    let v = self.u_n(d, false) * Vector4::from_column_slice(&x[or..or + 4]);
                    jc[or..or + 4].copy_from_slice(v.as_slice());
                }
                // X1 = ȦA_cᵀ − ȦAᵀG A A_cᵀ, G A A_cᵀ (r × r_j)
                for t in 0..rj {
                    for i in 0..r {
                        let (mut s1, mut s2) = (0.0, 0.0);
                        for k in 0..r {
                            let y = ws.aac[t * r + k];
                            s1 += ws.adag[k * r + i] * y;
                            s2 += ws.g[k * r + i] * y;
                        }
                        ws.x1[t * r + i] -= s1;
                        ws.gaac[t * r + i] = s2;
                    }
                }
                // ∂V = ∂ȦZ − ȦAᵀG V_c − X1 W_j − VΛᵀ into rows 0..r of sa,
                // ∂W = G V_c − G A A_cᵀ W_j − WΛᵀ into rows r..2r of sb
                let dw = ws.dw[j];
                // per row: (δ_i Z_c p) of the row's joint, and `Δω_j` on joint j's rows
                for (i, ir) in self.joints.iter().enumerate() {
                    let (ro, rr) = if R > 0 { (0, R) } else { (ir.offset, ir.rows) };
                    ws.rowd[ro..ro + rr].fill(ws.ddw[i]);
                }
                // (the running sums in a local array when they fit: with the row counts known
                // at compile time they stay in registers)
                let mut local = [0.0f64; 144];
                let lsum: &mut [f64] = if 4 * r * rj > local.len() {
                    let l = &mut ws.lsum[..4 * r * rj];
                    l.fill(0.0);
                    l
                } else {
                    &mut local[..4 * r * rj]
                };
                for c in 0..m {
                    let (dv, dwm) =
                        (&mut ws.sa[c * r2..c * r2 + r], &mut ws.sb[c * r2 + r..(c + 1) * r2]);
                    let (wc, vc) = (&ws.w[c * r + o..c * r + o + rj], &ws.vc[c * rj..(c + 1) * rj]);
                    let v2c = &ws.v2c[c * rj..(c + 1) * rj];
                    let wv: f64 = (0..rj).map(|t| wc[t] * vc[t]).sum();
                    let (vcol, wcol) = (&ws.v[c * r..(c + 1) * r], &ws.w[c * r..(c + 1) * r]);
                    let vth = &ws.vth[c * r..(c + 1) * r];
                    // −(XΛᵀ)_c = Σ_{l<c} X_l (v_lᵀ w_c + w_lᵀ v_c) + X_c w_c·v_c (X = V, W) by
                    // the running sums Σ_{l<c} X_l v_lᵀ, Σ_{l<c} X_l w_lᵀ (r × r_j each)
                    let (pv, rest) = lsum.split_at_mut(r * rj);
                    let (qv, rest) = rest.split_at_mut(r * rj);
                    let (pw, qw) = rest.split_at_mut(r * rj);
                    for i in 0..r {
                        let mut sv = ws.rowd[i] * vth[i] + vcol[i] * wv;
                        let mut sw = wcol[i] * wv;
                        if i >= o && i < o + rj {
                            sv += dw * v2c[i - o];
                        }
                        for t in 0..rj {
                            let (vct, wct) = (vc[t], wc[t]);
                            let k = (o + t) * r + i;
                            sv -= ws.adag[k] * vct + ws.x1[t * r + i] * wct;
                            sw += ws.g[k] * vct - ws.gaac[t * r + i] * wct;
                        }
                        let (pvi, qvi) =
                            (&mut pv[i * rj..(i + 1) * rj], &mut qv[i * rj..(i + 1) * rj]);
                        let (pwi, qwi) =
                            (&mut pw[i * rj..(i + 1) * rj], &mut qw[i * rj..(i + 1) * rj]);
                        for t in 0..rj {
                            sv += pvi[t] * wc[t] + qvi[t] * vc[t];
                            sw += pwi[t] * wc[t] + qwi[t] * vc[t];
                        }
                        dv[i] = sv;
                        dwm[i] = sw;
                        for t in 0..rj {
                            pvi[t] += vcol[i] * vc[t];
                            qvi[t] += vcol[i] * wc[t];
                            pwi[t] += wcol[i] * vc[t];
                            qwi[t] += wcol[i] * wc[t];
                        }
                    }
                }
                ws.dkp.fill(0.0);
                skew_apply(&ws.sa, &ws.sb, r2, p, &mut ws.dkp, &mut ws.rtmp);
                let jc = &mut jx[col * ns..col * ns + m];
                jc.iter_mut().zip(ws.colp.iter().zip(&ws.dkp)).for_each(|(j, (c, k))| *j = c - k);
                // the column g = ∂f̂/∂t into the in-plane columns as g tᵀ (`∂f̂/∂x̂ Π`)
                let (ca, cb) = jx[col * ns..].split_at_mut(self.nu * ns);
                for (ga, gb) in ca[..ns].iter_mut().zip(&mut cb[..ns]) {
                    *gb = a * *ga;
                    *ga *= -b;
                }
            }
        }
    }
}
