//! Right-hand side and exact Jacobian of the planar evaluation (module docs of
//! [`super`]; theory.md §10.4–10.5, §10.9), on the reduced fields `q̂1 = NᵀZ p` with the joint
//! rows only: `A` (`r × n`), `G = (AAᵀ)⁻¹`, `C0 = AẐ0`, `S = I − C0ᵀGC0 = LLᵀ` (generator form),
//! `H = GC0`, `W = HL⁻ᵀ`, `Ẑ = (Ẑ0 − AᵀH)L⁻ᵀ`.

use super::kernels::lowrank_right_solve_lt_padded;
use super::Planar;
use crate::error::{ModalError, Result};
use crate::exact_joints::ambient::AmbientOps;
use crate::exact_joints::eval::with_buffers;
use crate::exact_joints::frame::{gemv, gemv_t, lowrank_right_solve_lt, skew_apply};
use crate::exact_joints::model::{u_left, u_right};
use nalgebra::{Matrix4, Vector3, Vector4};
use std::cell::RefCell;

/// Reused buffers of one planar evaluation.
#[derive(Debug, Default)]
pub(crate) struct PlanarWs {
    key: Vec<usize>,
    pub(super) a: Vec<f64>,
    /// `A` row by row (`r` rows of `n`, each contiguous).
    pub(super) at: Vec<f64>,
    pub(super) gram: Vec<f64>,
    pub(super) linv: Vec<f64>,
    pub(super) g: Vec<f64>,
    pub(super) c0: Vec<f64>,
    pub(super) y: Vec<f64>,
    pub(super) h: Vec<f64>,
    pub(super) ld: Vec<f64>,
    pub(super) lh: Vec<f64>,
    pub(super) lmm: Vec<f64>,
    pub(super) lacc: Vec<f64>,
    pub(super) w: Vec<f64>,
    pub(super) z: Vec<f64>,
    /// `Zᵀ` (`m × n`, column-major).
    pub(super) zt: Vec<f64>,
    pub(super) q1: Vec<f64>,
    pub(super) q2: Vec<f64>,
    pub(super) f1: Vec<f64>,
    pub(super) f2: Vec<f64>,
    pub(super) jf: Vec<f64>,
    pub(super) amb: Vec<f64>,
    pub(super) ztf: Vec<f64>,
    pub(super) kp: Vec<f64>,
    /// Per joint (from `3 r o_j`): `A A_αᵀ` (`r × r_j` for `α = 1…3`, column `(α − 1) r_j + t`).
    pub(super) paa: Vec<f64>,
    /// `A_α Z` (`r × m`), `α = 1, 2, 3`; `V_θ = A_θ Z` and `V = ȦZ` (`r × m`).
    pub(super) az: [Vec<f64>; 3],
    pub(super) vth: Vec<f64>,
    pub(super) v: Vec<f64>,
    /// Per joint: `(c, s, ρ)`, `(a, b)`, `Δω`, `ξ̇_j`, `U(ω_b) − Ū(ω_a)`.
    pub(super) csr: Vec<[f64; 3]>,
    pub(super) ab: Vec<[f64; 2]>,
    pub(super) dw: Vec<f64>,
    pub(super) xid: Vec<Vector4<f64>>,
    pub(super) mj: Vec<Matrix4<f64>>,
    pub(super) rtmp: Vec<f64>,
    /// `J (Z_c p)` (`n + nb`).
    pub(super) tz: Vec<f64>,
    /// `J blockdiag(Z, Z2)` (`(n + nb) × max(m, m2)`).
    pub(super) tzm: Vec<f64>,
    /// `Zᵀ C` for the columns `C` of [`Planar::zcon`], row by row (`m × k`, row-major);
    /// `A C` (`r × k`).
    pub(super) ztc: Vec<f64>,
    /// The rows of the frame's one right solve (`Ẑ`, `W`, `A_α Z`, `(Zᵀ C)ᵀ`; `rs × m`) and
    /// the solve's `1 / d_i`.
    pub(super) stk: Vec<f64>,
    pub(super) rinv: Vec<f64>,
    pub(super) acz: Vec<f64>,
    pub(super) kap: Vec<f64>,
    pub(super) af1: Vec<f64>,
    pub(super) gaf: Vec<f64>,
    pub(super) pf1: Vec<f64>,
    pub(super) wp: Vec<f64>,
    pub(super) adat: Vec<f64>,
    pub(super) adag: Vec<f64>,
    pub(super) vc: Vec<f64>,
    pub(super) v2c: Vec<f64>,
    /// Running sums of the columns' `Λ` products (`4 r r_j`) when they do not fit the local
    /// array.
    pub(super) lsum: Vec<f64>,
    /// Per row: `δ_i Z_c p` of the row's joint (`r`).
    pub(super) rowd: Vec<f64>,
    pub(super) lp: Vec<f64>,
    pub(super) aac: Vec<f64>,
    pub(super) dd: Vec<f64>,
    pub(super) gd: Vec<f64>,
    pub(super) zcp: Vec<f64>,
    pub(super) colp: Vec<f64>,
    pub(super) dcp: Vec<f64>,
    pub(super) x1: Vec<f64>,
    pub(super) gaac: Vec<f64>,
    pub(super) dkp: Vec<f64>,
    pub(super) ddw: Vec<f64>,
    /// Per joint `α = 1…3`: `Ȧ A_αᵀ` (`r × r_j`), `A_α P f1` (`r_j`), `A_αᵀ (W p)_j` (`n`);
    /// the stacked `[∂V; V]`, `[W; ∂W]` (`2r × m`) of the columns' `∂(Kp)`.
    pub(super) ada: Vec<f64>,
    pub(super) apf: Vec<f64>,
    pub(super) atw: Vec<f64>,
    pub(super) sa: Vec<f64>,
    pub(super) sb: Vec<f64>,
    /// State length of the current call.
    pub(super) ns: usize,
}

thread_local! {
    static WS: RefCell<PlanarWs> = RefCell::new(PlanarWs::default());
}

/// Runs `f` with this thread's planar workspace sized for `pl`.
pub(crate) fn with_planar_workspace<T>(pl: &Planar, f: impl FnOnce(&mut PlanarWs) -> T) -> T {
    with_buffers(&WS, |ws| ws.key == pl.key, || PlanarWs::new(pl, pl.key.clone()), f)
}

fn z(n: usize) -> Vec<f64> {
    vec![0.0; n.max(1)]
}

impl PlanarWs {
    fn new(pl: &Planar, key: Vec<usize>) -> Self {
        let (n, m, r) = (pl.n, pl.m, pl.r);
        let nb = pl.nb;
        let nj = pl.joints.len();
        let rx = pl.joints.iter().map(|j| j.rows).max().unwrap_or(0);
        PlanarWs {
            key,
            a: z(r * n),
            at: z(r * n),
            gram: z(r * r),
            linv: z(r * r),
            g: z(r * r),
            c0: z(r * m),
            y: z(r * m),
            h: z(r * m),
            ld: z(m),
            lh: z(r * m),
            lmm: z(r * r),
            lacc: z(((n + 4 * r + pl.kc).div_ceil(4) * 4) * r),
            stk: z(((n + 4 * r + pl.kc).div_ceil(4) * 4) * m),
            rinv: z(m),
            paa: z(3 * r * r),
            w: z(r * m),
            z: z(n * m),
            zt: z(n * m),
            q1: z(n),
            q2: z(nb),
            f1: z(n),
            f2: z(nb),
            jf: z((n + nb) * (n + nb)),
            amb: z(pl.amb_len),
            ztf: z(m),
            kp: z(m),
            az: std::array::from_fn(|_| z(r * m)),
            vth: z(r * m),
            v: z(r * m),
            csr: vec![[0.0; 3]; nj],
            ab: vec![[0.0; 2]; nj],
            dw: z(nj),
            xid: vec![Vector4::zeros(); nj],
            mj: vec![Matrix4::zeros(); nj],
            rtmp: z(2 * r),
            tz: z(n + nb),
            tzm: z((n + nb) * m.max(pl.m2)),
            ztc: z(pl.kc * m),
            acz: z(pl.kc * r),
            kap: z(m),
            af1: z(r),
            gaf: z(r),
            pf1: z(n),
            wp: z(r),
            adat: z(r * r),
            adag: z(r * r),
            vc: z(rx * m),
            v2c: z(rx * m),
            lsum: z(4 * r * rx),
            rowd: z(r),
            lp: z(m),
            aac: z(r * rx),
            dd: z(r),
            gd: z(r),
            zcp: z(n),
            colp: z(m),
            dcp: z(rx),
            x1: z(r * rx),
            gaac: z(r * rx),
            dkp: z(m),
            ddw: z(nj),
            ada: z(3 * r * rx),
            apf: z(3 * rx),
            atw: z(3 * n),
            sa: z(2 * r * m),
            sb: z(2 * r * m),
            ns: 0,
        }
    }
}

/// `y = a x` (`a`: `rows × x.len()`, column-major).
fn mv(y: &mut [f64], a: &[f64], rows: usize, x: &[f64]) {
    gemv(y, false, a, rows, x, 1.0);
}

/// `y = aᵀ x` (`a`: `x.len() × y.len()`, column-major).
fn mtv(y: &mut [f64], a: &[f64], x: &[f64]) {
    gemv_t(y, false, a, x.len(), x, 1.0);
}

fn numerical(stage: &str, reason: &str) -> ModalError {
    ModalError::Numerical { stage: stage.to_string(), reason: reason.to_string() }
}

impl Planar {
    /// The sizes the workspace depends on.
    pub(super) fn dims_key(&self) -> Vec<usize> {
        let mut k = vec![self.n, self.m, self.m2, self.r, self.nb, self.amb_len];
        k.extend(self.joints.iter().map(|j| j.rows));
        k.extend(self.amb_key.iter().copied());
        k
    }

    /// `U(ω n)` with `ω` about the normal.
    pub(super) fn u_n(&self, w: f64, left: bool) -> Matrix4<f64> {
        let mut v = Vector3::zeros();
        v[self.nu - 1] = w;
        if left {
            u_left(&v)
        } else {
            u_right(&v)
        }
    }

    /// The frame `Ẑ(ξ)` and its factors into `ws` for the joint quaternions at `offsets`.
    #[inline(always)]
    fn frame<const R: usize>(
        &self,
        ws: &mut PlanarWs,
        x: &[f64],
        offsets: &[usize],
        want: bool,
    ) -> Result<()> {
        let (n, m) = (self.n, self.m);
        let r = if R > 0 { R } else { self.r };
        ws.a[..r * n].fill(0.0);
        ws.c0[..r * m].fill(0.0);
        for (j, jr) in self.joints.iter().enumerate() {
            let (a, b) = (x[offsets[j]], x[offsets[j] + self.nu]);
            let w = [1.0, a * a - b * b, 2.0 * a * b, a * a + b * b];
            ws.csr[j] = [w[1], w[2], w[3]];
            ws.ab[j] = [a, b];
            let (rj, o) = if R > 0 { (R, 0) } else { (jr.rows, jr.offset) };
            for (al, &wa) in w.iter().enumerate() {
                if al == 3 && jr.a3_zero {
                    continue;
                }
                for c in 0..n {
                    let src = &jr.a[al][c * rj..(c + 1) * rj];
                    let dst = &mut ws.a[c * r + o..c * r + o + rj];
                    dst.iter_mut().zip(src).for_each(|(d, s)| *d += wa * s);
                }
                for c in 0..m {
                    let src = &jr.az0[al][c * rj..(c + 1) * rj];
                    let dst = &mut ws.c0[c * r + o..c * r + o + rj];
                    dst.iter_mut().zip(src).for_each(|(d, s)| *d += wa * s);
                }
            }
        }
        // AAᵀ, its Cholesky factor and inverse, G
        for c in 0..n {
            for i in 0..r {
                ws.at[i * n + c] = ws.a[c * r + i];
            }
        }
        for i in 0..r {
            let ai = &ws.at[i * n..(i + 1) * n];
            for l in 0..=i {
                let al = &ws.at[l * n..(l + 1) * n];
                ws.gram[l * r + i] = ai.iter().zip(al).map(|(x, y)| x * y).sum();
            }
        }
        let scale = (0..r).fold(0.0f64, |mx, i| mx.max(ws.gram[i * r + i]));
        let li = &mut ws.linv;
        li[..r * r].fill(0.0);
        {
            let g = &mut ws.gram;
            for j in 0..r {
                let mut d = g[j * r + j];
                for k in 0..j {
                    d -= g[k * r + j] * g[k * r + j];
                }
                if d.is_nan() || d <= 1e-14 * scale {
                    return Err(numerical(
                        "Gram matrix of the joint rows AAᵀ",
                        "matrix is not positive definite (dependent rows)",
                    ));
                }
                let d = d.sqrt();
                g[j * r + j] = d;
                for i in j + 1..r {
                    let mut s = g[j * r + i];
                    for k in 0..j {
                        s -= g[k * r + i] * g[k * r + j];
                    }
                    g[j * r + i] = s / d;
                }
            }
            // L⁻¹ column by column
            for c in 0..r {
                li[c * r + c] = 1.0 / g[c * r + c];
                for i in c + 1..r {
                    let mut s = 0.0;
                    for k in c..i {
                        s -= g[k * r + i] * li[c * r + k];
                    }
                    li[c * r + i] = s / g[i * r + i];
                }
            }
        }
        for c in 0..r {
            for i in 0..r {
                let lo = i.max(c);
                ws.g[c * r + i] = (lo..r).map(|k| li[i * r + k] * li[c * r + k]).sum();
            }
        }
        // Y = L_g⁻¹ C0, S = I − YᵀY = LLᵀ, H = G C0, W = H L⁻ᵀ, Ẑ = (Ẑ0 − AᵀH) L⁻ᵀ
        for c in 0..m {
            for i in 0..r {
                let (mut y, mut h) = (0.0, 0.0);
                for k in 0..r {
                    let c0 = ws.c0[c * r + k];
                    y += ws.linv[k * r + i] * c0;
                    h += ws.g[k * r + i] * c0;
                }
                ws.y[c * r + i] = y;
                ws.h[c * r + i] = h;
            }
        }
        crate::exact_joints::frame::lowrank_cholesky(
            &ws.y,
            r,
            m,
            &mut ws.ld,
            &mut ws.lh,
            &mut ws.lmm,
            &mut ws.lacc,
            1e-10,
            "null-space basis Z(ξ)",
            "the joint rotation is outside the range of the fields (ZᵀP Z0 singular)",
        )?;
        // Everything right-multiplied by L⁻ᵀ is stacked as the rows of one matrix (`rs × m`,
        // rows padded to a multiple of four: the solve's vector chunks) and solved at once:
        // Ẑ0 − AᵀH (n), W's H (r), A_α Ẑ0 − (A_α Aᵀ)H (r per α: A_α Z without a product with
        // Z, A_α Ẑ0 a constant), and with the Jacobian (Ẑ0ᵀC − Hᵀ(A C))ᵀ for the constant
        // columns C of `zcon` (kc; A C = Σ_α w_α A_α C from constants)
        let alphas = if self.joints.iter().all(|j| j.a3_zero) { 2 } else { 3 };
        let kc = if want { self.kc } else { 0 };
        let (ow, oa, oc) = (n, n + r, n + r + alphas * r);
        let rs = (oc + kc).div_ceil(4) * 4;
        let stk = &mut ws.stk[..rs * m];
        for c in 0..m {
            let h = &ws.h[c * r..(c + 1) * r];
            let col = &mut stk[c * rs..(c + 1) * rs];
            // (Aᵀ H's columns as sums of A's rows, contiguous in `at`)
            let zc = &mut col[..n];
            zc.copy_from_slice(&self.z0[c * n..(c + 1) * n]);
            for (t, &ht) in h.iter().enumerate() {
                let at = &ws.at[t * n..(t + 1) * n];
                zc.iter_mut().zip(at).for_each(|(z, a)| *z -= ht * a);
            }
            col[ow..ow + r].copy_from_slice(h);
            col[oc + kc..].fill(0.0);
        }
        // A A_αᵀ from the constant A_jα A_iβᵀ
        for jr in &self.joints {
            let (rj, o) = if R > 0 { (R, 0) } else { (jr.rows, jr.offset) };
            let paa = &mut ws.paa[3 * r * o..3 * r * (o + rj)];
            for al in 0..alphas {
                for t in 0..rj {
                    for (k, kr) in self.joints.iter().enumerate() {
                        let [c, s, rho] = ws.csr[k];
                        let (kn, ko) = if R > 0 { (R, 0) } else { (kr.rows, kr.offset) };
                        for i in ko..ko + kn {
                            let e = |be: usize| jr.pa[((al * 4 + be) * rj + t) * r + i];
                            let mut v = e(0) + c * e(1) + s * e(2);
                            if !kr.a3_zero {
                                v += rho * e(3);
                            }
                            paa[(al * rj + t) * r + i] = v;
                        }
                    }
                }
                let az0 = &jr.az0[al + 1];
                for c in 0..m {
                    let h = &ws.h[c * r..(c + 1) * r];
                    for t in 0..rj {
                        let pt = &paa[(al * rj + t) * r..(al * rj + t + 1) * r];
                        let d: f64 = pt.iter().zip(h).map(|(a, b)| a * b).sum();
                        stk[c * rs + oa + al * r + o + t] = az0[c * rj + t] - d;
                    }
                }
            }
        }
        if kc > 0 {
            let acz = &mut ws.acz[..r * kc];
            acz.fill(0.0);
            for (j, jr) in self.joints.iter().enumerate() {
                let (rj, o) = if R > 0 { (R, 0) } else { (jr.rows, jr.offset) };
                let [c, s, rho] = ws.csr[j];
                let wgt = [1.0, c, s, rho];
                for (al, &wa) in wgt.iter().enumerate() {
                    for k in 0..kc {
                        let src = &jr.acon[al][k * rj..(k + 1) * rj];
                        let dst = &mut acz[k * r + o..k * r + o + rj];
                        dst.iter_mut().zip(src).for_each(|(d, v)| *d += wa * v);
                    }
                }
            }
            for i in 0..m {
                let h = &ws.h[i * r..(i + 1) * r];
                for k in 0..kc {
                    let d: f64 = h.iter().zip(&acz[k * r..(k + 1) * r]).map(|(a, b)| a * b).sum();
                    stk[i * rs + oc + k] = self.z0con[i * kc + k] - d;
                }
            }
        }
        if r <= 6 {
            lowrank_right_solve_lt_padded(&ws.y, &ws.lh, &ws.ld, r, stk, rs, &mut ws.rinv);
        } else {
            lowrank_right_solve_lt(&ws.y, &ws.lh, &ws.ld, r, &mut [(&mut *stk, rs)], &mut ws.lacc);
        }
        for c in 0..m {
            let col = &stk[c * rs..(c + 1) * rs];
            ws.z[c * n..(c + 1) * n].copy_from_slice(&col[..n]);
            for (i, &v) in col[..n].iter().enumerate() {
                ws.zt[i * m + c] = v;
            }
            ws.w[c * r..(c + 1) * r].copy_from_slice(&col[ow..ow + r]);
            for al in 0..alphas {
                ws.az[al][c * r..(c + 1) * r].copy_from_slice(&col[oa + al * r..oa + (al + 1) * r]);
            }
            ws.ztc[c * kc..(c + 1) * kc].copy_from_slice(&col[oc..oc + kc]);
        }
        Ok(())
    }

    /// Right-hand side into `f` and, with `jac`, the exact Jacobians, at a planar state
    /// ([`Planar::accepts`]); `offsets`: the joint quaternions' offsets, `root`: the root
    /// quaternion's offset when carried.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn eval(
        &self,
        ops: &AmbientOps,
        ws: &mut PlanarWs,
        x: &[f64],
        u: &[f64],
        offsets: &[usize],
        root: Option<usize>,
        f: &mut [f64],
        jac: Option<(&mut [f64], &mut [f64])>,
    ) -> Result<()> {
        // one revolute joint (two rows): row counts known at compile time
        if self.r == 2 && self.joints.len() == 1 {
            self.eval_imp::<2>(ops, ws, x, u, offsets, root, f, jac)
        } else {
            self.eval_imp::<0>(ops, ws, x, u, offsets, root, f, jac)
        }
    }

    /// [`Planar::eval`]; `R > 0`: one joint of `R` rows.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn eval_imp<const R: usize>(
        &self,
        ops: &AmbientOps,
        ws: &mut PlanarWs,
        x: &[f64],
        u: &[f64],
        offsets: &[usize],
        root: Option<usize>,
        f: &mut [f64],
        jac: Option<(&mut [f64], &mut [f64])>,
    ) -> Result<()> {
        let (n, m, m2) = (self.n, self.m, self.m2);
        let r = if R > 0 { R } else { self.r };
        let nb = self.nb;
        ws.ns = f.len();
        let want = jac.is_some();
        self.frame::<R>(ws, x, offsets, want)?;
        let (p, p2) = (&x[..m], &x[m..m + m2]);
        mv(&mut ws.q1, &ws.z, n, p);
        if self.z2_identity {
            ws.q2.copy_from_slice(p2);
        } else {
            mv(&mut ws.q2, &self.z2, nb, p2);
        }
        let jf = if want { Some(&mut ws.jf[..]) } else { None };
        ops.eval(&ws.q1, &ws.q2, u, &mut ws.f1, &mut ws.f2, jf, &mut ws.amb);
        mtv(&mut ws.ztf, &ws.z[..n * m], &ws.f1);
        // joint rates, ξ̇_j, V = ȦZ = Δω A_θ Z (`A_α Z` from the frame)
        for (j, jr) in self.joints.iter().enumerate() {
            let dot = |row: &[f64]| row.iter().zip(&ws.q1).map(|(a, b)| a * b).sum::<f64>();
            let (wa, wb) = (dot(&jr.wa), dot(&jr.wb));
            ws.dw[j] = wb - wa;
            ws.mj[j] = self.u_n(wb, false) - self.u_n(wa, true);
            let o = offsets[j];
            ws.xid[j] = ws.mj[j] * Vector4::from_column_slice(&x[o..o + 4]);
            let [c, s, _] = ws.csr[j];
            let dw = ws.dw[j];
            let (rj, o) = if R > 0 { (R, 0) } else { (jr.rows, jr.offset) };
            for col in 0..m {
                for i in o..o + rj {
                    let vt = -s * ws.az[0][col * r + i] + c * ws.az[1][col * r + i];
                    ws.vth[col * r + i] = vt;
                    ws.v[col * r + i] = dw * vt;
                }
            }
        }
        ws.kp.fill(0.0);
        skew_apply(&ws.v, &ws.w, r, p, &mut ws.kp, &mut ws.rtmp);
        for i in 0..m {
            f[i] = ws.ztf[i] - ws.kp[i];
        }
        if self.z2_identity {
            f[m..m + m2].copy_from_slice(&ws.f2);
        } else {
            mtv(&mut f[m..m + m2], &self.z2, &ws.f2);
        }
        let root_w = self.root.as_ref().map(|t| t.iter().zip(&ws.q1).map(|(a, b)| a * b).sum());
        if let (Some(o), Some(w)) = (root, root_w) {
            let d = self.u_n(w, false) * Vector4::from_column_slice(&x[o..o + 4]);
            f[o..o + 4].copy_from_slice(d.as_slice());
        }
        for (j, &o) in offsets.iter().enumerate() {
            f[o..o + 4].copy_from_slice(ws.xid[j].as_slice());
        }
        if let Some((jx, ju)) = jac {
            self.jacobian::<R>(ws, x, u.len(), offsets, root.zip(root_w), jx, ju);
        }
        Ok(())
    }
}
