//! Right-hand side and exact Jacobian of the exact-joints model (theory.md §10.4–10.5),
//! evaluated through the joints' end-node rows.
//!
//! Every joint row is `A_j(ξ) = C_j(ξ) E_j` with `E_j` the fields' values at the joint's two end
//! nodes (`2k × na`, constant) and `C_j` small and linear in `R(ξ_j)`; support rows `S` are
//! constant (and absent once the model has reduced its fields by them, theory.md §10.3). So
//! every product of `A`, `Ȧ`, `∂A/∂ξ` with `Z(ξ) = (Z0 − AᵀH) L⁻ᵀ`
//! (`H = G A Z0`, theory.md §10.4) reduces to products of the precomputed `E_j Z0`, `E_j Sᵀ`,
//! `E_j E_iᵀ`, `S Sᵀ` with `r × ·` matrices: the `ξ` columns of the Jacobian cost
//! `O(na (m + r) + m r²)` each, the `p` columns are `ZᵀJ11Z − K − κ Ξ` (`κ_jc = K(∂A/∂ξ_jc) p`,
//! `Ξ = ∂ξ̇/∂p`, a rank-`4·joints` term), and the dense work is the projection `ZᵀJZ` of the
//! ambient Jacobian.

use crate::error::Result;
use crate::exact_joints::columns::Batch;
use crate::exact_joints::frame::{
    cholesky, gemm, gemv, gemv_t, lowrank_cholesky, lowrank_right_solve_lt, lowrank_solve_l,
    lowrank_solve_lt, skew_apply, view, view_mut,
};
use crate::exact_joints::model::{u_left, u_right, ExactJointsRom};
use nalgebra::{Matrix4, Vector3, Vector4};
use std::cell::RefCell;
use std::thread::LocalKey;

/// Reused buffers of one evaluation (sized by the model's dimensions).
#[derive(Debug, Default)]
pub(crate) struct Workspace {
    pub(super) key: Vec<usize>,
    /// Per joint: `C_j` and `∂C_j/∂ξ_c` (`r_j × 2k`).
    pub(super) c: Vec<Vec<f64>>,
    pub(super) dc: Vec<[Vec<f64>; 4]>,
    /// Per joint: `Ċ_j` and its change `Ċ'_j` along one joint-quaternion column (`r_j × 2k`).
    pub(super) cdot: Vec<Vec<f64>>,
    pub(super) cdot2: Vec<Vec<f64>>,
    /// Per tracked block: `T Aᵀ` (`t × r`), `T Z` (`t × m`).
    pub(super) ta: Vec<Vec<f64>>,
    pub(super) tz: Vec<Vec<f64>>,
    pub(super) gram: Vec<f64>,
    pub(super) g: Vec<f64>,
    pub(super) c0: Vec<f64>,
    pub(super) h: Vec<f64>,
    pub(super) w: Vec<f64>,
    /// `W` restricted to all joint rows (`rJ × m`) and to each joint's rows (`r_j × m`).
    pub(super) wj: Vec<f64>,
    pub(super) wjj: Vec<Vec<f64>>,
    /// Cholesky factor `L` of `S = I − YᵀY` in generator form: `Y`, `H` (`rJ × m`), the diagonal
    /// (`m`) (frame::lowrank_cholesky), its `rJ × rJ` scratch and a `max(na, r, t) × rJ` scratch.
    pub(super) ly: Vec<f64>,
    pub(super) lh: Vec<f64>,
    pub(super) ld: Vec<f64>,
    pub(super) lmm: Vec<f64>,
    pub(super) lacc: Vec<f64>,
    pub(super) z: Vec<f64>,
    /// `Zᵀ` (`m × na`), column-major (with `Z`).
    pub(super) zt: Vec<f64>,
    /// Per joint: `C_jᵀ` (`2k × r_j`).
    pub(super) ct: Vec<Vec<f64>>,
    pub(super) q1: Vec<f64>,
    pub(super) q2: Vec<f64>,
    pub(super) f1: Vec<f64>,
    pub(super) f2: Vec<f64>,
    pub(super) jf: Vec<f64>,
    /// `E_j q1` per joint (`2k`), root node `E_r q1` (`k`): per tracked block.
    pub(super) eq: Vec<Vec<f64>>,
    pub(super) xi: Vec<Vector4<f64>>,
    pub(super) xi_dot: Vec<Vector4<f64>>,
    /// `V = ȦZ` on the joint rows (`rJ × m`); `∂A/∂ξ_jc Z` per joint and `c` (`r_j × m`).
    pub(super) v: Vec<f64>,
    pub(super) vc: Vec<[Vec<f64>; 4]>,
    /// `∂ξ̇_j/∂p` (`4 × m`) per joint.
    pub(super) xi_p: Vec<Vec<f64>>,
    pub(super) ztf: Vec<f64>,
    pub(super) t11: Vec<f64>,
    pub(super) u21: Vec<f64>,
    pub(super) t12: Vec<f64>,
    pub(super) mm: Vec<f64>,
    pub(super) adat: Vec<f64>,
    pub(super) adat_g: Vec<f64>,
    pub(super) dv: Vec<f64>,
    pub(super) rtmp: Vec<f64>,
    pub(super) ktmp: Vec<f64>,
    pub(super) mtmp2: Vec<f64>,
    pub(super) big: Vec<f64>,
    pub(super) af1: Vec<f64>,
    pub(super) gf: Vec<f64>,
    pub(super) zc: Vec<f64>,
    pub(super) epf: Vec<Vec<f64>>,
    pub(super) wp: Vec<f64>,
    pub(super) tj: Vec<f64>,
    pub(super) dxd: Vec<Vector4<f64>>,
    /// `y = L⁻ᵀ p` (`m`) and `H y` (`r`) of [`ExactJointsRom::apply_z`].
    pub(super) py: Vec<f64>,
    pub(super) hy: Vec<f64>,
    /// `U(ω_b) − Ū(ω_a)` per joint.
    pub(super) mjs: Vec<Matrix4<f64>>,
    pub(super) dkp: Vec<f64>,
    pub(super) ambient_tmp: Vec<f64>,
    /// The batched joint-quaternion columns' buffers.
    pub(super) batch: Batch,
}

thread_local! {
    static WORKSPACE: RefCell<Workspace> = RefCell::new(Workspace::default());
}

/// Runs `f` with this thread's buffers in `cell`, rebuilt by `make` unless `fits` says they
/// are sized for the model at hand (the evaluations' reused workspaces).
pub(crate) fn with_buffers<W: 'static, T>(
    cell: &'static LocalKey<RefCell<W>>,
    fits: impl FnOnce(&W) -> bool,
    make: impl FnOnce() -> W,
    f: impl FnOnce(&mut W) -> T,
) -> T {
    cell.with(|ws| {
        let mut ws = ws.borrow_mut();
        if !fits(&ws) {
            *ws = make();
        }
        f(&mut ws)
    })
}

/// Runs `f` with this thread's workspace sized for `rom`.
pub(crate) fn with_workspace<T>(rom: &ExactJointsRom, f: impl FnOnce(&mut Workspace) -> T) -> T {
    with_buffers(&WORKSPACE, |ws| rom.dims_match(&ws.key), || Workspace::new(rom), f)
}

fn zeros(n: usize) -> Vec<f64> {
    vec![0.0; n]
}

impl Workspace {
    fn new(rom: &ExactJointsRom) -> Self {
        let (na, nb, m, m2) = (rom.basis.n1(), rom.basis.n2(), rom.n_p(), rom.n_p2());
        let r = rom.cons.n_rows();
        let rs = rom.cons.support.nrows();
        let rj = r - rs;
        let joints = &rom.cons.joints;
        let per = |f: &dyn Fn(usize, usize) -> usize| -> Vec<Vec<f64>> {
            joints.iter().map(|j| zeros(f(j.rows, j.e.nrows()))).collect()
        };
        let kk = joints.iter().map(|j| j.e.nrows()).max().unwrap_or(0);
        let rmax = joints.iter().map(|j| j.rows).max().unwrap_or(0).max(r);
        let big = (2 * m * r).max(2 * r * r).max(m * m).max(na * m).max(kk * m).max(nb * m2);
        Workspace {
            key: rom.dims_key(),
            c: per(&|rj, kk| rj * kk),
            dc: joints
                .iter()
                .map(|j| std::array::from_fn(|_| zeros(j.rows * j.e.nrows())))
                .collect(),
            cdot: per(&|rj, kk| rj * kk),
            cdot2: per(&|rj, kk| rj * kk),
            ta: rom.tracked.iter().map(|t| zeros(t.rows.nrows() * r)).collect(),
            tz: rom.tracked.iter().map(|t| zeros(t.rows.nrows() * m)).collect(),
            gram: zeros(r * r),
            g: zeros(r * r),
            c0: zeros(r * m),
            h: zeros(r * m),
            w: zeros(r * m),
            wj: zeros(rj * m),
            wjj: per(&|rj, _| rj * m),
            ly: zeros(rj * m),
            lh: zeros(rj * m),
            ld: zeros(m),
            lmm: zeros(rj * rj),
            lacc: zeros(
                (na + r + rom.tracked.iter().map(|t| t.rows.nrows()).sum::<usize>()).max(1)
                    * rj.max(1),
            ),
            z: zeros(na * m),
            zt: zeros(na * m),
            ct: per(&|rj, kk| rj * kk),
            q1: zeros(na),
            q2: zeros(nb),
            f1: zeros(na),
            f2: zeros(nb),
            jf: zeros((na + nb) * (na + nb)),
            eq: rom.tracked.iter().map(|t| zeros(t.rows.nrows())).collect(),
            xi: vec![Vector4::zeros(); joints.len() + 1],
            xi_dot: vec![Vector4::zeros(); joints.len() + 1],
            v: zeros(rj * m),
            vc: joints.iter().map(|j| std::array::from_fn(|_| zeros(j.rows * m))).collect(),
            xi_p: joints.iter().map(|_| zeros(4 * m)).collect(),
            ztf: zeros(m),
            t11: zeros(m * na),
            u21: zeros(m2.max(nb) * na),
            t12: zeros(m * nb),
            mm: zeros(m * m.max(m2)),
            adat: zeros(rj * r),
            adat_g: zeros(rj * rmax),
            dv: zeros(rj * m),
            rtmp: zeros(r.max(kk).max(1) * 4),
            ktmp: zeros(kk.max(1)),
            mtmp2: zeros(m),
            big: zeros(big.max(1)),
            af1: zeros(r),
            gf: zeros(r),
            zc: zeros(na),
            epf: joints.iter().map(|j| zeros(j.e.nrows())).collect(),
            wp: zeros(r),
            tj: zeros(rmax),
            dxd: vec![Vector4::zeros(); joints.len()],
            mjs: vec![Matrix4::zeros(); joints.len()],
            py: zeros(m),
            hy: zeros(r),
            dkp: zeros(m),
            ambient_tmp: zeros(rom.ops.scratch_len()),
            batch: Batch::new(rom),
        }
    }
}

/// `ω_a`, `ω_b` of a joint from its end-node values `e` (`2k`), or the root's `ω` from its
/// node values (`k`).
pub(super) fn rates(rom: &ExactJointsRom, e: &[f64], end: usize) -> Vector3<f64> {
    let k = rom.basis.layout.k();
    let mut w = Vector3::zeros();
    for &(c, axis) in &rom.rate_comps {
        w[axis] = e[end * k + c];
    }
    w
}

/// `ξ̇ = (U(ω_b) − Ū(ω_a)) ξ` of a joint (or `U(ω) ξ` of the root) as a linear map of the
/// tracked values `e`: `ξ̇ = Σ_k e[i_k] v_k` over the rate components (theory.md §10.4), with
/// `v_k = U(e_axis) ξ` (end `b`, root) or `−Ū(e_axis) ξ` (end `a`).
#[derive(Debug, Default)]
pub(crate) struct RateMap {
    terms: [(usize, Vector4<f64>); 6],
    len: usize,
}

impl RateMap {
    /// The map of a joint (`joint`, ends `a` then `b` in `e`) or of the root node at `xi`.
    pub(super) fn new(rom: &ExactJointsRom, xi: &Vector4<f64>, joint: bool) -> Self {
        let k = rom.basis.layout.k();
        let mut terms = [(0, Vector4::zeros()); 6];
        let mut len = 0;
        for &(c, axis) in &rom.rate_comps {
            let w = Vector3::ith(axis, 1.0);
            if joint {
                terms[len] = (c, -(u_left(&w) * xi));
                terms[len + 1] = (k + c, u_right(&w) * xi);
                len += 2;
            } else {
                terms[len] = (c, u_right(&w) * xi);
                len += 1;
            }
        }
        RateMap { terms, len }
    }

    /// The map as a `4 × t` matrix (column-major) into `d` (`t` tracked values).
    pub(super) fn matrix(&self, d: &mut [f64]) {
        d.fill(0.0);
        for (i, v) in &self.terms[..self.len] {
            d[4 * i..4 * i + 4].copy_from_slice(v.as_slice());
        }
    }

    /// `ξ̇` for the tracked values `e`.
    #[inline]
    pub(super) fn apply(&self, e: &[f64]) -> Vector4<f64> {
        self.terms[..self.len].iter().fold(Vector4::zeros(), |acc, (i, v)| acc + v * e[*i])
    }
}

/// `U(ω_b) − Ū(ω_a)` of joint block `e`.
pub(super) fn joint_rate_matrix(rom: &ExactJointsRom, e: &[f64]) -> Matrix4<f64> {
    u_right(&rates(rom, e, 1)) - u_left(&rates(rom, e, 0))
}

impl ExactJointsRom {
    /// The factors of `Z(ξ)` into `ws` for the joint rotations in `x` (theory.md §10.4), and
    /// with `with_z` the `na × m` matrix `Z` itself (the Jacobian needs it;
    /// the right-hand side applies `Z` through its factors, [`ExactJointsRom::apply_z`]).
    pub(crate) fn frame_into(&self, ws: &mut Workspace, x: &[f64], with_z: bool) -> Result<()> {
        let (na, m) = (self.basis.n1(), self.n_p());
        let r = self.cons.n_rows();
        let rs = self.cons.support.nrows();
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let o = self.joint_offset(j);
            ws.xi[j] = Vector4::from_column_slice(&x[o..o + 4]);
            let [d0, d1, d2, d3] = &mut ws.dc[j];
            jr.coefficients(&ws.xi[j], &mut ws.c[j], &mut [d0, d1, d2, d3]);
            let (rjj, kk) = (jr.rows, jr.e.nrows());
            for col in 0..kk {
                for row in 0..rjj {
                    ws.ct[j][row * kk + col] = ws.c[j][col * rjj + row];
                }
            }
        }
        // T Aᵀ = [T Sᵀ | T E_iᵀ C_iᵀ]
        for (t, tr) in self.tracked.iter().enumerate() {
            let nt = tr.rows.nrows();
            let ta = &mut ws.ta[t];
            ta[..nt * rs].copy_from_slice(&tr.s[..nt * rs]);
            for (i, jr) in self.cons.joints.iter().enumerate() {
                let o = self.row_offsets[i];
                let kk = jr.e.nrows();
                gemm(
                    view_mut(&mut ta[o * nt..], nt, jr.rows),
                    false,
                    view(&tr.e[i], nt, kk),
                    view(&ws.c[i], jr.rows, kk).transpose(),
                    1.0,
                );
            }
        }
        // AAᵀ: support block SSᵀ, joint j's rows C_j (E_j Aᵀ) (all columns), the support rows'
        // joint columns by symmetry, the joint–joint blocks symmetrised
        {
            let mut gm = view_mut(&mut ws.gram, r, r);
            for c in 0..rs {
                for i in 0..rs {
                    gm[(i, c)] = self.ss[c * rs + i];
                }
            }
            for (j, jr) in self.cons.joints.iter().enumerate() {
                let o = self.row_offsets[j];
                let kk = jr.e.nrows();
                gemm(
                    gm.as_mut().submatrix_mut(o, 0, jr.rows, r),
                    false,
                    view(&ws.c[j], jr.rows, kk),
                    view(&ws.ta[j], kk, r),
                    1.0,
                );
            }
            for c in rs..r {
                for i in 0..rs {
                    gm[(i, c)] = gm[(c, i)];
                }
                for i in rs..c {
                    let s = 0.5 * (gm[(i, c)] + gm[(c, i)]);
                    gm[(i, c)] = s;
                    gm[(c, i)] = s;
                }
            }
        }
        cholesky(
            &mut ws.gram,
            r,
            1e-14,
            true,
            "Gram matrix of the joint rows AAᵀ",
            "matrix is not positive definite (dependent rows)",
        )?;
        // G = L_g⁻ᵀ L_g⁻¹
        {
            let inv = &mut ws.big[..r * r];
            inv.fill(0.0);
            for i in 0..r {
                inv[i * r + i] = 1.0;
            }
            if r > 0 {
                faer::linalg::triangular_solve::solve_lower_triangular_in_place(
                    view(&ws.gram, r, r),
                    view_mut(inv, r, r),
                    faer::Par::Seq,
                );
            }
            gemm(
                view_mut(&mut ws.g, r, r),
                false,
                view(inv, r, r).transpose(),
                view(inv, r, r),
                1.0,
            );
        }
        // C0 = A Z0 (support rows vanish on Z0)
        {
            ws.c0.fill(0.0);
            let mut c0 = view_mut(&mut ws.c0, r, m);
            for (j, jr) in self.cons.joints.iter().enumerate() {
                let kk = jr.e.nrows();
                gemm(
                    c0.as_mut().subrows_mut(self.row_offsets[j], jr.rows),
                    false,
                    view(&ws.c[j], jr.rows, kk),
                    view(&self.tracked[j].z0, kk, m),
                    1.0,
                );
            }
        }
        gemm(view_mut(&mut ws.h, r, m), false, view(&ws.g, r, r), view(&ws.c0, r, m), 1.0);
        // S = I − C0ᵀ G C0 = I − YᵀY with Y = L_g⁻¹[J, J] C0_J (C0 vanishes on the support
        // rows and L_g⁻¹ is lower triangular, so G[J, J] = L_g⁻¹[J, J]ᵀ L_g⁻¹[J, J]) = L Lᵀ, `L` in
        // generator form (frame::lowrank_cholesky)
        {
            let rj = r - rs;
            gemm(
                view_mut(&mut ws.ly, rj, m),
                false,
                view(&ws.big, r, r).submatrix(rs, rs, rj, rj),
                view(&ws.c0, r, m).subrows(rs, rj),
                1.0,
            );
            lowrank_cholesky(
                &ws.ly,
                rj,
                m,
                &mut ws.ld,
                &mut ws.lh,
                &mut ws.lmm,
                &mut ws.lacc,
                1e-10,
                "null-space basis Z(ξ)",
                "the joint rotation is outside the range of the fields (ZᵀP Z0 singular)",
            )?;
        }
        let rj = r - rs;
        ws.w.copy_from_slice(&ws.h);
        // T Z = (T Z0 − T Aᵀ H) L⁻ᵀ
        for (t, tr) in self.tracked.iter().enumerate() {
            let nt = tr.rows.nrows();
            ws.tz[t].copy_from_slice(&tr.z0);
            gemm(
                view_mut(&mut ws.tz[t], nt, m),
                true,
                view(&ws.ta[t], nt, r),
                view(&ws.h, r, m),
                -1.0,
            );
        }
        // Z = (Z0 − AᵀH) L⁻ᵀ, AᵀH = SᵀH_s + Σ E_jᵀ C_jᵀ H_j
        if with_z {
            ws.z.copy_from_slice(self.z0_flat());
            let hv = view(&ws.h, r, m);
            gemm(
                view_mut(&mut ws.z, na, m),
                true,
                view(self.support_t_flat(), na, rs),
                hv.subrows(0, rs),
                -1.0,
            );
            for (j, jr) in self.cons.joints.iter().enumerate() {
                let kk = jr.e.nrows();
                let tmp = &mut ws.big[..kk * m];
                gemm(
                    view_mut(tmp, kk, m),
                    false,
                    view(&ws.ct[j], kk, jr.rows),
                    hv.subrows(self.row_offsets[j], jr.rows),
                    1.0,
                );
                gemm(
                    view_mut(&mut ws.z, na, m),
                    true,
                    view(self.e_t_flat(j), na, kk),
                    view(tmp, kk, m),
                    -1.0,
                );
            }
        }
        // W = H L⁻ᵀ, T Z, Z: the right solves in one pass
        {
            // the list on the stack for up to six tracked blocks (no allocation per evaluation)
            const STACK: usize = 8;
            let count = self.tracked.len() + 1 + usize::from(with_z);
            let mut stack: [(&mut [f64], usize); STACK] = std::array::from_fn(|_| (&mut [][..], 0));
            let mut heap = Vec::new();
            let xs = if count <= STACK {
                &mut stack[..count]
            } else {
                heap.resize_with(count, || (&mut [][..], 0));
                &mut heap[..]
            };
            xs[0] = (&mut ws.w[..], r);
            for ((x, tz), tr) in xs[1..].iter_mut().zip(ws.tz.iter_mut()).zip(&self.tracked) {
                *x = (&mut tz[..], tr.rows.nrows());
            }
            if with_z {
                xs[count - 1] = (&mut ws.z[..], na);
            }
            lowrank_right_solve_lt(&ws.ly, &ws.lh, &ws.ld, rj, xs, &mut ws.lacc);
        }
        if with_z {
            for c in 0..m {
                for (i, v) in ws.z[c * na..(c + 1) * na].iter().enumerate() {
                    ws.zt[i * m + c] = *v;
                }
            }
        }
        // W on the joint rows
        for c in 0..m {
            ws.wj[c * (r - rs)..(c + 1) * (r - rs)].copy_from_slice(&ws.w[c * r + rs..(c + 1) * r]);
            for (j, jr) in self.cons.joints.iter().enumerate() {
                let o = self.row_offsets[j];
                ws.wjj[j][c * jr.rows..(c + 1) * jr.rows]
                    .copy_from_slice(&ws.w[c * r + o..c * r + o + jr.rows]);
            }
        }
        Ok(())
    }

    /// `A v` (`r`) for a field vector `v` (`na`).
    pub(crate) fn rows_times(
        &self,
        ws_c: &[Vec<f64>],
        v: &[f64],
        out: &mut [f64],
        tmp: &mut [f64],
    ) {
        let rs = self.cons.support.nrows();
        gemv(&mut out[..rs], false, self.support_flat(), rs, v, 1.0);
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let kk = jr.e.nrows();
            let ev = &mut tmp[..kk];
            gemv(ev, false, self.e_flat(j), kk, v, 1.0);
            let o = self.row_offsets[j];
            gemv(&mut out[o..o + jr.rows], false, &ws_c[j], jr.rows, ev, 1.0);
        }
    }

    /// `out (+)= alpha · Aᵀ u` (`na`) for a row vector `u` (`r`).
    pub(crate) fn rows_t_times(
        &self,
        ws_c: &[Vec<f64>],
        u: &[f64],
        alpha: f64,
        out: &mut [f64],
        tmp: &mut [f64],
    ) {
        let rs = self.cons.support.nrows();
        let na = self.basis.n1();
        let s = self.support_flat();
        gemv_t(out, true, s, rs, &u[..rs], alpha);
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let kk = jr.e.nrows();
            let o = self.row_offsets[j];
            let cu = &mut tmp[..kk];
            gemv_t(cu, false, &ws_c[j], jr.rows, &u[o..o + jr.rows], 1.0);
            gemv_t(&mut out[..na], true, self.e_flat(j), kk, cu, alpha);
        }
    }

    /// `q1 = Z p = Z0 y − Aᵀ(H y)` with `y = L⁻ᵀ p` (theory.md §10.4), from the factors of
    /// [`ExactJointsRom::frame_into`]: `O(na m + m²)` without forming `Z`.
    fn apply_z(&self, ws: &mut Workspace, p: &[f64]) {
        let (na, r) = (self.basis.n1(), self.cons.n_rows());
        let rj = r - self.cons.support.nrows();
        // Lᵀ y = p
        let y = &mut ws.py;
        y.copy_from_slice(p);
        lowrank_solve_lt(&ws.ly, &ws.lh, &ws.ld, rj, y, &mut ws.lacc);
        gemv(&mut ws.hy, false, &ws.h, r, y, 1.0);
        gemv(&mut ws.q1, false, self.z0_flat(), na, y, 1.0);
        self.rows_t_times(&ws.c, &ws.hy, -1.0, &mut ws.q1, &mut ws.ktmp);
    }

    /// `Zᵀf1 = L⁻¹ (Z0ᵀ f1 − Hᵀ(A f1))` into `ws.ztf` (and `A f1` into `ws.af1`).
    fn apply_z_t(&self, ws: &mut Workspace) {
        let (na, r) = (self.basis.n1(), self.cons.n_rows());
        let rj = r - self.cons.support.nrows();
        self.rows_times(&ws.c, &ws.f1, &mut ws.af1, &mut ws.ktmp);
        let t = &mut ws.ztf;
        gemv_t(t, false, self.z0_flat(), na, &ws.f1, 1.0);
        gemv_t(t, true, &ws.h, r, &ws.af1, -1.0);
        // L t = ·
        lowrank_solve_l(&ws.ly, &ws.lh, &ws.ld, rj, t, &mut ws.lacc);
    }

    /// Right-hand side into `f`, and with `jac = Some((jx, ju))` the exact Jacobians
    /// (theory.md §10.5); the state and input are checked by the caller.
    pub(crate) fn eval_into(
        &self,
        ws: &mut Workspace,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        jac: Option<(&mut [f64], &mut [f64])>,
    ) -> Result<()> {
        let (nb, m, m2) = (self.basis.n2(), self.n_p(), self.n_p2());
        let r = self.cons.n_rows();
        let rs = self.cons.support.nrows();
        let rj = r - rs;
        let nj = self.n_joints();
        self.frame_into(ws, x, jac.is_some())?;
        let p = &x[..m];
        let p2 = &x[m..m + m2];
        self.apply_z(ws, p);
        if self.z2_identity {
            ws.q2.copy_from_slice(p2);
        } else {
            gemv(&mut ws.q2, false, self.z2_flat(), nb, p2, 1.0);
        }
        let jf = if jac.is_some() { Some(&mut ws.jf[..]) } else { None };
        self.ops.eval(&ws.q1, &ws.q2, u, &mut ws.f1, &mut ws.f2, jf, &mut ws.ambient_tmp);
        for (t, tr) in self.tracked.iter().enumerate() {
            gemv(&mut ws.eq[t], false, &ws.tz[t], tr.rows.nrows(), p, 1.0);
        }
        for j in 0..nj {
            ws.xi_dot[j] = joint_rate_matrix(self, &ws.eq[j]) * ws.xi[j];
        }
        let root_xi = self.root_quaternion(x);
        let root_dot = root_xi.map(|xr| u_right(&rates(self, &ws.eq[nj], 0)) * xr);
        // V = ȦZ on the joint rows: Ċ_j (E_j Z)
        for (j, jr) in self.cons.joints.iter().enumerate() {
            let kk = jr.e.nrows();
            let cd = &mut ws.cdot[j];
            cd.fill(0.0);
            for c in 0..4 {
                let s = ws.xi_dot[j][c];
                cd.iter_mut().zip(&ws.dc[j][c]).for_each(|(a, b)| *a += s * b);
            }
            gemm(
                view_mut(&mut ws.v, rj, m).subrows_mut(self.row_offsets[j] - rs, jr.rows),
                false,
                view(cd, jr.rows, kk),
                view(&ws.tz[j], kk, m),
                1.0,
            );
        }
        // ṗ = Zᵀf1 − K p
        self.apply_z_t(ws);
        let kp = &mut ws.mtmp2;
        kp.fill(0.0);
        skew_apply(&ws.v, &ws.wj, rj, p, kp, &mut ws.rtmp);
        for i in 0..m {
            f[i] = ws.ztf[i] - kp[i];
        }
        if self.z2_identity {
            f[m..m + m2].copy_from_slice(&ws.f2);
        } else {
            gemv_t(&mut f[m..m + m2], false, self.z2_flat(), nb, &ws.f2, 1.0);
        }
        if let Some(d) = root_dot {
            let o = self.root_offset();
            f[o..o + 4].copy_from_slice(d.as_slice());
        }
        for j in 0..nj {
            let o = self.joint_offset(j);
            f[o..o + 4].copy_from_slice(ws.xi_dot[j].as_slice());
        }
        if let Some((jx, ju)) = jac {
            self.jacobian_into(ws, x, root_xi, jx, ju);
        }
        Ok(())
    }
}
