//! Exact Jacobian of the exact-joints model (theory.md §10.5) from the factors of
//! [`super::eval`].
//!
//! `∂f/∂(p, p2)`: `ZᵀJ11Z − K − κΞ`, `ZᵀJ12Z2`, `Z2ᵀJ21Z`, `Z2ᵀJ22Z2` with `κ_jc = K(∂A/∂ξ_jc)p`
//! and `Ξ = ∂ξ̇/∂p`. `∂f/∂ξ_jc` with `A_c = ∂A/∂ξ_jc`, `V_c = A_cZ`, `Λ_c = Φ(−(WᵀV_c + V_cᵀW))`:
//!
//! ```text
//!   Z_c p   = −AᵀG(V_c p − A A_cᵀ W p) − A_cᵀ W p − Z Λ_cᵀ p
//!   Z_cᵀ f1 = −V_cᵀ G A f1 − Wᵀ A_c P f1 − Λ_c Zᵀ f1
//!   ∂V      = ∂Ȧ Z − ȦAᵀG V_c − (ȦA_cᵀ − ȦAᵀG A A_cᵀ) W − V Λ_cᵀ
//!   ∂W      = ∂G B + G ∂B = G V_c − G A A_cᵀ W − W Λ_cᵀ
//!             (∂G = −G(A_cAᵀ + AA_cᵀ)G, ∂B = V_c + A_cAᵀ W − B Λ_cᵀ, W = GB, B = AZ̃)
//!   ∂(Kp)   = K(∂V, W) p + K(V, ∂W) p
//! ```
//!
//! `∂Ȧ` from the change of every `ξ̇` (through `Z_c p` and, for joint `j`, `ξ_j` itself) and
//! the constant `∂²A/∂ξ²`. Where `A_c = 0` exactly (a planar model's out-of-plane quaternion
//! components at an in-plane rotation) `Z_c = 0`, `∂W = 0`, and the column is `ξ̇_j`'s own
//! term and `−K(∂Ȧ Z, W) p`.

use crate::exact_joints::eval::{joint_rate_matrix, rates, RateMap, Workspace};
use crate::exact_joints::frame::{gemm, gemv, skew_apply, view, view_mut};
use crate::exact_joints::model::{u_right, ExactJointsRom};
use nalgebra::Vector4;

/// The workspace pieces [`ExactJointsRom::dadot_z`] reads and writes.
struct DadotZ<'a> {
    dxd: &'a [Vector4<f64>],
    xi_dot: &'a [Vector4<f64>],
    dc: &'a [[Vec<f64>; 4]],
    tz: &'a [Vec<f64>],
    cdot2: &'a mut [Vec<f64>],
    dv: &'a mut [f64],
}

impl ExactJointsRom {
    /// The Jacobians into `jx` (`n × n`) and `ju` (`n × inputs`), column-major, after
    /// [`ExactJointsRom::eval_into`] filled `ws` at the same state.
    pub(super) fn jacobian_into(
        &self,
        ws: &mut Workspace,
        x: &[f64],
        root_xi: Option<Vector4<f64>>,
        jx: &mut [f64],
        ju: &mut [f64],
    ) {
        let (na, nb, m, m2) = (self.basis.n1(), self.basis.n2(), self.n_p(), self.n_p2());
        let (n, nu) = (self.n_state(), self.n_inputs());
        let r = self.cons.n_rows();
        let rs = self.cons.support.nrows();
        let rj = r - rs;
        let nj = self.n_joints();
        jx.fill(0.0);
        ju.fill(0.0);
        let nf = na + nb;
        let jf = view(&ws.jf, nf, nf);
        let z = view(&ws.z, na, m);
        let zt = view(&ws.zt, m, na);
        // ZᵀJ11Z, Z2ᵀJ21Z, ZᵀJ12Z2, Z2ᵀJ22Z2 (link by link when J is block-diagonal by link)
        let j21 = jf.submatrix(na, 0, nb, na);
        let j22 = jf.submatrix(na, na, nb, nb);
        match self.ops.link_blocks() {
            Some(blocks) if self.z2_identity => {
                for ((o1, k1), (o2, k2)) in blocks {
                    let (zb, zbt) = (z.subrows(o1, k1), zt.subcols(o1, k1));
                    gemm(
                        view_mut(&mut ws.t11, m, na).subcols_mut(o1, k1),
                        false,
                        zbt,
                        jf.submatrix(o1, o1, k1, k1),
                        1.0,
                    );
                    gemm(
                        view_mut(&mut ws.t12, m, nb).subcols_mut(o2, k2),
                        false,
                        zbt,
                        jf.submatrix(o1, na + o2, k1, k2),
                        1.0,
                    );
                    gemm(
                        view_mut(jx, n, n).submatrix_mut(m + o2, 0, k2, m),
                        false,
                        jf.submatrix(na + o2, o1, k2, k1),
                        zb,
                        1.0,
                    );
                }
            }
            _ => {
                gemm(view_mut(&mut ws.t11, m, na), false, zt, jf.submatrix(0, 0, na, na), 1.0);
                gemm(view_mut(&mut ws.t12, m, nb), false, zt, jf.submatrix(0, na, na, nb), 1.0);
                let u21 = if self.z2_identity {
                    j21
                } else {
                    gemm(view_mut(&mut ws.u21, m2, na), false, self.z2.transpose(), j21, 1.0);
                    view(&ws.u21, m2, na)
                };
                gemm(view_mut(jx, n, n).submatrix_mut(m, 0, m2, m), false, u21, z, 1.0);
            }
        }
        gemm(view_mut(jx, n, n).submatrix_mut(0, 0, m, m), false, view(&ws.t11, m, na), z, 1.0);
        if self.z2_identity {
            view_mut(jx, n, n).submatrix_mut(0, m, m, m2).copy_from(view(&ws.t12, m, nb));
            view_mut(jx, n, n).submatrix_mut(m, m, m2, m2).copy_from(j22);
        } else {
            gemm(
                view_mut(jx, n, n).submatrix_mut(0, m, m, m2),
                false,
                view(&ws.t12, m, nb),
                self.z2.as_ref(),
                1.0,
            );
            gemm(view_mut(&mut ws.big, nb, m2), false, j22, self.z2.as_ref(), 1.0);
            gemm(
                view_mut(jx, n, n).submatrix_mut(m, m, m2, m2),
                false,
                self.z2.transpose(),
                view(&ws.big, nb, m2),
                1.0,
            );
        }
        // − K: K_il = M_li (i < l), −M_il (i > l), M = VᵀW
        gemm(
            view_mut(&mut ws.mm, m, m),
            false,
            view(&ws.v, rj, m).transpose(),
            view(&ws.wj, rj, m),
            1.0,
        );
        gemm(
            view_mut(&mut ws.big, m, m),
            false,
            view(&ws.wj, rj, m).transpose(),
            view(&ws.v, rj, m),
            1.0,
        );
        for l in 0..m {
            let col = &mut jx[l * n..l * n + m];
            col[..l].iter_mut().zip(&ws.big[l * m..l * m + l]).for_each(|(v, w)| *v -= w);
            col[l + 1..]
                .iter_mut()
                .zip(&ws.mm[l * m + l + 1..(l + 1) * m])
                .for_each(|(v, w)| *v += w);
        }
        // Ξ = ∂ξ̇/∂p (joint and root rows): D (T Z) with ξ̇ = D e (`RateMap`) on the tracked values
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let kk = jr.e.nrows();
            let o = self.joint_offset(j);
            let d = &mut ws.rtmp[..4 * kk];
            RateMap::new(self, &ws.xi[j], true).matrix(d);
            gemm(
                view_mut(jx, n, n).submatrix_mut(o, 0, 4, m),
                false,
                view(d, 4, kk),
                view(&ws.tz[j], kk, m),
                1.0,
            );
            for k in 0..m {
                ws.xi_p[j][k * 4..(k + 1) * 4].copy_from_slice(&jx[k * n + o..k * n + o + 4]);
            }
        }
        if let Some(xr) = root_xi {
            let kr = self.tracked[nj].rows.nrows();
            let o = self.root_offset();
            let d = &mut ws.rtmp[..4 * kr];
            RateMap::new(self, &xr, false).matrix(d);
            gemm(
                view_mut(jx, n, n).submatrix_mut(o, 0, 4, m),
                false,
                view(d, 4, kr),
                view(&ws.tz[nj], kr, m),
                1.0,
            );
            let ur = u_right(&rates(self, &ws.eq[nj], 0));
            for c in 0..4 {
                for i in 0..4 {
                    jx[(o + c) * n + o + i] = ur[(i, c)];
                }
            }
        }
        // V_c = ∂A/∂ξ_jc Z (the term − κ Ξ, κ_jc = K(V_c, W_j) p, with the joint columns: κ_jc = 0
        // where ∂A/∂ξ_jc = 0, and V_c is read only where it is not)
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let kk = jr.e.nrows();
            for c in 0..4 {
                if ws.dc[j][c].iter().all(|&v| v == 0.0) {
                    continue;
                }
                gemm(
                    view_mut(&mut ws.vc[j][c], jr.rows, m),
                    false,
                    view(&ws.dc[j][c], jr.rows, kk),
                    view(&ws.tz[j], kk, m),
                    1.0,
                );
            }
        }
        // inputs: ZᵀB_u
        for c in 0..nu {
            gemv(&mut ju[c * n..c * n + m], false, &ws.zt, m, self.ops.b_u.col_as_slice(c), 1.0);
        }
        if nj == 0 {
            return;
        }
        self.joint_columns(ws, x, root_xi, jx);
    }

    /// The columns of the joint quaternions (module docs).
    fn joint_columns(
        &self,
        ws: &mut Workspace,
        x: &[f64],
        root_xi: Option<Vector4<f64>>,
        jx: &mut [f64],
    ) {
        let m = self.n_p();
        let n = self.n_state();
        let r = self.cons.n_rows();
        let rs = self.cons.support.nrows();
        let rj = r - rs;
        let nj = self.n_joints();
        let p = &x[..m];
        // G A f1 (A f1 from the right-hand side), P f1, E_j P f1, W p, ȦAᵀ
        gemv(&mut ws.gf, false, &ws.g, r, &ws.af1, 1.0);
        ws.zc.copy_from_slice(&ws.f1);
        self.rows_t_times(&ws.c, &ws.gf, -1.0, &mut ws.zc, &mut ws.ktmp);
        for (j, jr) in self.cons.joints.iter().enumerate() {
            gemv(&mut ws.epf[j], false, self.e_flat(j), jr.e.nrows(), &ws.zc, 1.0);
        }
        gemv(&mut ws.wp, false, &ws.w, r, p, 1.0);
        for (i, ir) in self.cons.joints.iter().enumerate() {
            gemm(
                view_mut(&mut ws.adat, rj, r).subrows_mut(self.row_offsets[i] - rs, ir.rows),
                false,
                view(&ws.cdot[i], ir.rows, ir.e.nrows()),
                view(&ws.ta[i], ir.e.nrows(), r),
                1.0,
            );
        }
        for j in 0..nj {
            ws.mjs[j] = joint_rate_matrix(self, &ws.eq[j]);
        }
        self.stack_vw(ws);
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let (rjj, o) = (jr.rows, self.row_offsets[j]);
            // A_cᵀ-free pieces shared by the four c: G[:, rows j], ȦAᵀ G[:, rows j]
            gemm(
                view_mut(&mut ws.adat_g, rj, rjj),
                false,
                view(&ws.adat, rj, r),
                view(&ws.g, r, r).subcols(o, rjj),
                1.0,
            );
            let mut cs = [0usize; 4];
            let mut nc = 0;
            for c in 0..4 {
                let col = self.joint_offset(j) + c;
                if ws.dc[j][c].iter().all(|&v| v == 0.0) {
                    // ∂A/∂ξ_jc = 0 (a planar joint's out-of-plane components): Z, W, V do not
                    // move (Z_c = 0, so the p2, root and other joints' rows are 0), only ξ̇_j's
                    // own dependence on ξ_j and the resulting ∂Ȧ remain.
                    let oj = self.joint_offset(j);
                    for (i, d) in ws.dxd.iter_mut().enumerate() {
                        *d = if i == j {
                            ws.mjs[j].column(c).into_owned()
                        } else {
                            Vector4::zeros()
                        };
                    }
                    jx[col * n + oj..col * n + oj + 4].copy_from_slice(ws.dxd[j].as_slice());
                    self.dadot_z(
                        DadotZ {
                            dxd: &ws.dxd,
                            xi_dot: &ws.xi_dot,
                            dc: &ws.dc,
                            tz: &ws.tz,
                            cdot2: &mut ws.cdot2,
                            dv: &mut ws.dv,
                        },
                        j,
                        c,
                    );
                    let t = &mut ws.dkp;
                    t.fill(0.0);
                    skew_apply(&ws.dv, &ws.wj, rj, p, t, &mut ws.rtmp);
                    for i in 0..m {
                        jx[col * n + i] = -t[i];
                    }
                } else {
                    cs[nc] = c;
                    nc += 1;
                }
            }
            if nc > 0 {
                self.joint_block(ws, p, root_xi, jx, j, &cs[..nc]);
            }
        }
    }

    /// `∂Ȧ Z` on the joint rows into `ws.dv` for the column of `ξ_jc`, from the changes
    /// `ws.dxd` of every joint's `ξ̇` and the constant `∂²A/∂ξ_jc∂ξ_jd`.
    fn dadot_z(&self, ws: DadotZ<'_>, j: usize, c: usize) {
        let m = self.n_p();
        let rs = self.cons.support.nrows();
        let rj = self.cons.n_rows() - rs;
        let jr = &self.cons.joints[j];
        for (i, ir) in self.cons.joints.iter().enumerate() {
            let cd = &mut ws.cdot2[i];
            cd.fill(0.0);
            for d in 0..4 {
                let s = ws.dxd[i][d];
                cd.iter_mut().zip(&ws.dc[i][d]).for_each(|(a, b)| *a += s * b);
            }
            if i == j {
                for d in 0..4 {
                    let s = ws.xi_dot[j][d];
                    if s != 0.0 {
                        let c2 = &jr.c2[4 * c + d];
                        cd.iter_mut().zip(c2.iter()).for_each(|(a, b)| *a += s * b);
                    }
                }
            }
            gemm(
                view_mut(ws.dv, rj, m).subrows_mut(self.row_offsets[i] - rs, ir.rows),
                false,
                view(cd, ir.rows, ir.e.nrows()),
                view(&ws.tz[i], ir.e.nrows(), m),
                1.0,
            );
        }
    }
}
