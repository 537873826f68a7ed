//! The joint-quaternion columns of the exact Jacobian (theory.md §10.5), all moving columns of
//! one joint at once (those with `∂A/∂ξ_jc ≠ 0`: four in 3D, two at a planar model's in-plane
//! joint rotation): the `na`-long pieces `Z_c p` of the `nc` columns form one `na × nc` matrix,
//! so their products with `ZᵀJ11`, `Z2ᵀJ21`, the tracked rows and `Z` are single products with
//! `nc` columns; the row-space pieces `[∂V_c; ∂W_c]` (`2r_J × m` each) are kept as
//! [`LANES`] values per entry, one per column `c`, built by one product per joint (`∂Ȧ Z`,
//! `−ȦAᵀG V_c` and `G[J, j] V_c` all have the form `(· ∂C_jc)(E_i Z)`) and one product with
//! `W_j` (`−X1_c W_j`, `−G A A_cᵀ W_j`); the running-sum recurrences (the triangle
//! applications `Λ_cᵀp`, `Λ_c Zᵀf1`, `−[V; W_J]Λ_cᵀ`, and the skew applications `κ_jc`,
//! `∂(Kp)`) advance all `c` together, one vector operation per step, compiled for the
//! processor's vector instructions by pulp's run-time dispatch (as faer's kernels). Module docs
//! of [`super::jacobian`] for the formulas.

use crate::exact_joints::eval::{RateMap, Workspace};
use crate::exact_joints::frame::{gemm, gemv, gemv_t, small_size, view, view_mut};
use crate::exact_joints::model::ExactJointsRom;
use faer::traits::pulp::{Arch, Simd, WithSimd};
use nalgebra::Vector4;

/// Buffers of the batched joint columns (`nc ≤ 4` columns per joint).
#[derive(Debug, Default)]
pub(crate) struct Batch {
    lp: Vec<f64>,
    a1: Vec<f64>,
    d: Vec<f64>,
    gd: Vec<f64>,
    zc: Vec<f64>,
    cg: Vec<f64>,
    colp: Vec<f64>,
    u2: Vec<f64>,
    eqc: Vec<Vec<f64>>,
    dxd: Vec<Vector4<f64>>,
    /// `ξ̇_i` as linear maps of the tracked values, per joint.
    maps: Vec<RateMap>,
    lm: Vec<f64>,
    cd: Vec<f64>,
    dct: Vec<f64>,
    aac: Vec<f64>,
    gaac: Vec<f64>,
    x1: Vec<f64>,
    x1tmp: Vec<f64>,
    rm: Vec<f64>,
    /// `[∂V_c; ∂W_c]` (`2rj × m`) and `V_c` (`r_j × m`), lanes.
    dvw: Vec<L>,
    vcs: Vec<L>,
    /// `[V; W_J]` (`2rj × m`).
    pvw: Vec<f64>,
    s1: Vec<L>,
    s2: Vec<f64>,
    sal: Vec<L>,
    sw: Vec<f64>,
    sd: Vec<L>,
    sv: Vec<f64>,
    lanes: Vec<L>,
}

impl Batch {
    pub(crate) fn new(rom: &ExactJointsRom) -> Self {
        let (na, m, m2) = (rom.basis.n1(), rom.n_p(), rom.n_p2());
        let r = rom.cons.n_rows();
        let rj = r - rom.cons.support.nrows();
        let joints = &rom.cons.joints;
        let kx = joints.iter().map(|j| j.e.nrows()).max().unwrap_or(0);
        let rx = joints.iter().map(|j| j.rows).max().unwrap_or(0);
        let z = |n: usize| vec![0.0; n];
        Batch {
            lp: z(4 * m),
            a1: z(4 * kx),
            d: z(4 * r),
            gd: z(4 * r),
            zc: z(4 * na),
            cg: z(4 * kx),
            colp: z(4 * m),
            u2: z(4 * m2),
            eqc: rom.tracked.iter().map(|t| z(4 * t.rows.nrows())).collect(),
            dxd: vec![Vector4::zeros(); 4 * joints.len()],
            maps: joints.iter().map(|_| RateMap::default()).collect(),
            lm: z(LANES * 2 * rj * kx),
            cd: z(rx * kx),
            dct: z(4 * kx * rx),
            aac: z(4 * r * rx),
            gaac: z(4 * r * rx),
            x1: z(4 * rj * rx),
            x1tmp: z(4 * kx * rx),
            rm: z(LANES * 2 * rj * rx),
            dvw: vec![[0.0; LANES]; 2 * rj * m],
            vcs: vec![[0.0; LANES]; rx * m],
            pvw: z(2 * rj * m),
            s1: vec![[0.0; LANES]; 2 * rj * rx],
            s2: z(2 * rj * rx),
            sal: vec![[0.0; LANES]; rx],
            sw: z(rx),
            sd: vec![[0.0; LANES]; 2 * rj],
            sv: z(2 * rj),
            lanes: vec![[0.0; LANES]; m],
        }
    }
}

/// Lanes: one value per moving column `c` of a joint (up to four), side by side, so that each
/// step of the single-column recurrences below is one vector operation for all columns.
pub(crate) const LANES: usize = 4;
type L = [f64; LANES];

#[inline(always)]
fn axpy(acc: &mut L, s: f64, x: &L) {
    for (a, x) in acc.iter_mut().zip(x) {
        *a = s.mul_add(*x, *a);
    }
}

/// One of the lane kernels below, run by [`Arch::dispatch`] so that it is compiled for the
/// processor's vector instruction set (the kernels are `#[inline(always)]` into `with_simd`).
enum Kernel<'a> {
    Phi {
        a: &'a [L],
        w: &'a [f64],
        ra: usize,
        p: &'a [f64],
        upper: bool,
        alpha: f64,
        out: &'a mut [L],
        sa: &'a mut [L],
        sw: &'a mut [f64],
    },
    RightPhi {
        pm: &'a [f64],
        q: usize,
        a: &'a [L],
        w: &'a [f64],
        ra: usize,
        m: usize,
        out: &'a mut [L],
        s1: &'a mut [L],
        s2: &'a mut [f64],
        dl: &'a mut [L],
    },
    Kappa {
        a: &'a [L],
        w: &'a [f64],
        ra: usize,
        p: &'a [f64],
        out: &'a mut [L],
        sa: &'a mut [L],
        sw: &'a mut [f64],
    },
    Skew {
        dvw: &'a [L],
        pvw: &'a [f64],
        rj: usize,
        p: &'a [f64],
        t: &'a mut [L],
        sd: &'a mut [L],
        sv: &'a mut [f64],
    },
}

impl WithSimd for Kernel<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        match self {
            Kernel::Phi { a, w, ra, p, upper, alpha, out, sa, sw } => small_size!(
                ra,
                phi_apply_const(a, w, p, upper, alpha, out),
                phi_apply_lanes(a, w, ra, p, upper, alpha, out, sa, sw)
            ),
            Kernel::RightPhi { pm, q, a, w, ra, m, out, s1, s2, dl } => small_size!(
                ra,
                right_phi_t_rows(pm, q, a, w, m, out, dl),
                right_phi_t_lanes(pm, q, a, w, ra, m, out, s1, s2)
            ),
            Kernel::Kappa { a, w, ra, p, out, sa, sw } => {
                small_size!(ra, kappa_const(a, w, p, out), kappa_lanes(a, w, ra, p, out, sa, sw))
            }
            Kernel::Skew { dvw, pvw, rj, p, t, sd, sv } => match rj {
                1 => skew_const::<2>(dvw, pvw, p, t),
                2 => skew_const::<4>(dvw, pvw, p, t),
                3 => skew_const::<6>(dvw, pvw, p, t),
                4 => skew_const::<8>(dvw, pvw, p, t),
                5 => skew_const::<10>(dvw, pvw, p, t),
                6 => skew_const::<12>(dvw, pvw, p, t),
                _ => skew_lanes(dvw, pvw, rj, p, t, sd, sv),
            },
        }
    }
}

/// [`phi_apply_lanes`] with `ra = RA` and its running sums in local arrays (registers).
#[inline(always)]
fn phi_apply_const<const RA: usize>(
    a: &[L],
    w: &[f64],
    p: &[f64],
    upper: bool,
    alpha: f64,
    out: &mut [L],
) {
    let (mut sa, mut sw) = ([[0.0; LANES]; RA], [0.0; RA]);
    phi_apply_lanes(a, w, RA, p, upper, alpha, out, &mut sa, &mut sw)
}

/// [`kappa_lanes`] with `ra = RA` and its running sums in local arrays (registers).
#[inline(always)]
fn kappa_const<const RA: usize>(a: &[L], w: &[f64], p: &[f64], out: &mut [L]) {
    let (mut sa, mut sw) = ([[0.0; LANES]; RA], [0.0; RA]);
    kappa_lanes(a, w, RA, p, out, &mut sa, &mut sw)
}

/// `out += alpha · Φ(aᵀw + wᵀa)ᵀ p` (`upper`) or `alpha · Φ(aᵀw + wᵀa) p` per lane
/// ([`super::frame::phi_apply`]): `a` lanes (`ra × m`), `w` (`ra × m`) and `p` (`m`) shared.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn phi_apply_lanes(
    a: &[L],
    w: &[f64],
    ra: usize,
    p: &[f64],
    upper: bool,
    alpha: f64,
    out: &mut [L],
    sa: &mut [L],
    sw: &mut [f64],
) {
    let m = p.len();
    let (sa, sw) = (&mut sa[..ra], &mut sw[..ra]);
    sa.fill([0.0; LANES]);
    sw.fill(0.0);
    for idx in 0..m {
        let i = if upper { m - 1 - idx } else { idx };
        let (ai, wi) = (&a[i * ra..(i + 1) * ra], &w[i * ra..(i + 1) * ra]);
        let h = 0.5 * p[i];
        for k in 0..ra {
            axpy(&mut sa[k], h, &ai[k]);
            sw[k] = h.mul_add(wi[k], sw[k]);
        }
        let mut v = [0.0; LANES];
        for k in 0..ra {
            axpy(&mut v, sw[k], &ai[k]);
            axpy(&mut v, wi[k], &sa[k]);
        }
        axpy(&mut out[i], alpha, &v);
        for k in 0..ra {
            axpy(&mut sa[k], h, &ai[k]);
            sw[k] = h.mul_add(wi[k], sw[k]);
        }
    }
}

/// `out = K(a, w) p` per lane: `out_i = w_iᵀ Σ_{l>i} p_l a_l − a_iᵀ Σ_{l<i} p_l w_l`
/// ([`super::frame::skew_apply`]; `a` lanes and `w`: `ra × m`).
#[inline(always)]
fn kappa_lanes(
    a: &[L],
    w: &[f64],
    ra: usize,
    p: &[f64],
    out: &mut [L],
    sa: &mut [L],
    sw: &mut [f64],
) {
    let m = p.len();
    let (sa, sw, out) = (&mut sa[..ra], &mut sw[..ra], &mut out[..m]);
    out.fill([0.0; LANES]);
    sa.fill([0.0; LANES]);
    for i in (0..m).rev() {
        let (ai, wi) = (&a[i * ra..(i + 1) * ra], &w[i * ra..(i + 1) * ra]);
        for k in 0..ra {
            axpy(&mut out[i], wi[k], &sa[k]);
        }
        for k in 0..ra {
            axpy(&mut sa[k], p[i], &ai[k]);
        }
    }
    sw.fill(0.0);
    for i in 0..m {
        let (ai, wi) = (&a[i * ra..(i + 1) * ra], &w[i * ra..(i + 1) * ra]);
        for k in 0..ra {
            axpy(&mut out[i], -sw[k], &ai[k]);
        }
        for k in 0..ra {
            sw[k] = p[i].mul_add(wi[k], sw[k]);
        }
    }
}

/// `out_l += S1 w_l + S2 a_l + (a_l·w_l) P_l` per lane over columns `l` with running sums
/// `S1 = Σ_{i<l} P_i a_iᵀ` (lanes), `S2 = Σ_{i<l} P_i w_iᵀ` (shared): `out += −P Φ(X)ᵀ`,
/// `X = −(aᵀw + wᵀa)` (`P`: `q × m`; `a` lanes and `w`: `ra × m`; `out` lanes: `q × m`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn right_phi_t_lanes(
    pm: &[f64],
    q: usize,
    a: &[L],
    w: &[f64],
    ra: usize,
    m: usize,
    out: &mut [L],
    s1: &mut [L],
    s2: &mut [f64],
) {
    let (s1, s2) = (&mut s1[..q * ra], &mut s2[..q * ra]);
    s1.fill([0.0; LANES]);
    s2.fill(0.0);
    for l in 0..m {
        let pl = &pm[l * q..(l + 1) * q];
        let al = &a[l * ra..(l + 1) * ra];
        let wl = &w[l * ra..(l + 1) * ra];
        let mut d = [0.0; LANES];
        for k in 0..ra {
            axpy(&mut d, wl[k], &al[k]);
        }
        let ol = &mut out[l * q..(l + 1) * q];
        // row s of the running sums read once: the term of column l, then the update
        for s in 0..q {
            let ps = pl[s];
            let mut acc = [0.0; LANES];
            axpy(&mut acc, ps, &d);
            let (c1, c2) = (&mut s1[s * ra..(s + 1) * ra], &mut s2[s * ra..(s + 1) * ra]);
            for k in 0..ra {
                axpy(&mut acc, wl[k], &c1[k]);
                axpy(&mut acc, c2[k], &al[k]);
                axpy(&mut c1[k], ps, &al[k]);
                c2[k] = ps.mul_add(wl[k], c2[k]);
            }
            for (o, x) in ol[s].iter_mut().zip(&acc) {
                *o += x;
            }
        }
    }
}

/// [`right_phi_t_lanes`] row by row of `P` (the same sums in the same order for each entry):
/// the running sums `S1[s, ·]` (lanes) and `S2[s, ·]` of one row `s` stay in registers over
/// all columns `l` (`RA = ra` a constant); `dl`: `m` lanes of scratch for `a_l·w_l`.
#[inline(always)]
fn right_phi_t_rows<const RA: usize>(
    pm: &[f64],
    q: usize,
    a: &[L],
    w: &[f64],
    m: usize,
    out: &mut [L],
    dl: &mut [L],
) {
    let dl = &mut dl[..m];
    for (l, d) in dl.iter_mut().enumerate() {
        let (al, wl) = (&a[l * RA..(l + 1) * RA], &w[l * RA..(l + 1) * RA]);
        *d = [0.0; LANES];
        for k in 0..RA {
            axpy(d, wl[k], &al[k]);
        }
    }
    for s in 0..q {
        let mut c1 = [[0.0; LANES]; RA];
        let mut c2 = [0.0; RA];
        for l in 0..m {
            let al: &[L; RA] = a[l * RA..(l + 1) * RA].try_into().expect("lanes");
            let wl: &[f64; RA] = w[l * RA..(l + 1) * RA].try_into().expect("row");
            let ps = pm[l * q + s];
            let mut acc = [0.0; LANES];
            axpy(&mut acc, ps, &dl[l]);
            for k in 0..RA {
                axpy(&mut acc, wl[k], &c1[k]);
                axpy(&mut acc, c2[k], &al[k]);
                axpy(&mut c1[k], ps, &al[k]);
                c2[k] = ps.mul_add(wl[k], c2[k]);
            }
            for (o, x) in out[l * q + s].iter_mut().zip(&acc) {
                *o += x;
            }
        }
    }
}

/// [`skew_lanes`] with `2 rj = Q` and its running sums in local arrays.
#[inline(always)]
fn skew_const<const Q: usize>(dvw: &[L], pvw: &[f64], p: &[f64], t: &mut [L]) {
    let (mut sd, mut sv) = ([[0.0; LANES]; Q], [0.0; Q]);
    skew_lanes(dvw, pvw, Q / 2, p, t, &mut sd, &mut sv)
}

/// `t = K(∂V, W) p + K(V, ∂W) p` per lane with `dvw` lanes `[∂V; ∂W]` (`2rj × m`) and
/// `pvw = [V; W]` (`2rj × m`); `K(a, b)p_i = b_iᵀ Σ_{l>i} p_l a_l − a_iᵀ Σ_{l<i} p_l b_l`
/// ([`super::frame::skew_apply`]).
#[inline(always)]
fn skew_lanes(
    dvw: &[L],
    pvw: &[f64],
    rj: usize,
    p: &[f64],
    t: &mut [L],
    sd: &mut [L],
    sv: &mut [f64],
) {
    let m = p.len();
    let q = 2 * rj;
    let (sd, sv) = (&mut sd[..q], &mut sv[..q]);
    let t = &mut t[..m];
    t.fill([0.0; LANES]);
    // suffix sums Σ_{l>i} p_l [∂V; ∂W]_l (lanes) and Σ_{l>i} p_l [V; W]_l
    sd.fill([0.0; LANES]);
    sv.fill(0.0);
    for i in (0..m).rev() {
        let (col, pv) = (&dvw[i * q..(i + 1) * q], &pvw[i * q..(i + 1) * q]);
        for s in 0..rj {
            axpy(&mut t[i], pv[rj + s], &sd[s]);
            axpy(&mut t[i], sv[s], &col[rj + s]);
        }
        for s in 0..q {
            axpy(&mut sd[s], p[i], &col[s]);
            sv[s] = p[i].mul_add(pv[s], sv[s]);
        }
    }
    // prefix sums Σ_{l<i} p_l [∂V; ∂W]_l (lanes) and Σ_{l<i} p_l [V; W]_l
    sd.fill([0.0; LANES]);
    sv.fill(0.0);
    for i in 0..m {
        let (col, pv) = (&dvw[i * q..(i + 1) * q], &pvw[i * q..(i + 1) * q]);
        for s in 0..rj {
            axpy(&mut t[i], -sv[rj + s], &col[s]);
            axpy(&mut t[i], -pv[s], &sd[rj + s]);
        }
        for s in 0..q {
            axpy(&mut sd[s], p[i], &col[s]);
            sv[s] = p[i].mul_add(pv[s], sv[s]);
        }
    }
}

impl ExactJointsRom {
    /// `[V; W_J]` (`2rj × m`) for [`ExactJointsRom::joint_block`], once per evaluation.
    pub(super) fn stack_vw(&self, ws: &mut Workspace) {
        let m = self.n_p();
        let rj = self.cons.n_rows() - self.cons.support.nrows();
        let pvw = &mut ws.batch.pvw;
        for l in 0..m {
            pvw[l * 2 * rj..l * 2 * rj + rj].copy_from_slice(&ws.v[l * rj..(l + 1) * rj]);
            pvw[l * 2 * rj + rj..(l + 1) * 2 * rj].copy_from_slice(&ws.wj[l * rj..(l + 1) * rj]);
        }
    }

    /// The columns `cs` (components with `∂A/∂ξ_jc ≠ 0`) of joint `j` into `jx` (module docs).
    /// Needs the shared pieces of [`super::jacobian`]: `G A f1` (`gf`), `E_j P f1` (`epf`),
    /// `W p` (`wp`), `ȦAᵀ` (`adat`), `ȦAᵀ G[:, rows j]` (`adat_g`), `U(ω_b) − Ū(ω_a)` (`mjs`),
    /// `A_c Z` (`vc`) and [`ExactJointsRom::stack_vw`].
    pub(super) fn joint_block(
        &self,
        ws: &mut Workspace,
        p: &[f64],
        root_xi: Option<Vector4<f64>>,
        jx: &mut [f64],
        j: usize,
        cs: &[usize],
    ) {
        let (na, m, m2) = (self.basis.n1(), self.n_p(), self.n_p2());
        let n = self.n_state();
        let r = self.cons.n_rows();
        let rs = self.cons.support.nrows();
        let rj = r - rs;
        let nj = self.n_joints();
        let jr = &self.cons.joints[j];
        let (rjj, kk, o) = (jr.rows, jr.e.nrows(), self.row_offsets[j]);
        let nc = cs.len();
        let q = 2 * rj;
        let bt = &mut ws.batch;
        let wjj = &ws.wjj[j];
        // V_c of all c as lanes
        let vcs = &mut bt.vcs[..rjj * m];
        vcs.fill([0.0; LANES]);
        for (b, &c) in cs.iter().enumerate() {
            for (v, x) in vcs.iter_mut().zip(&ws.vc[j][c]) {
                v[b] = *x;
            }
        }
        // − κ Ξ in the p columns, κ_jc = K(V_c, W_j) p, Ξ = ∂ξ̇_j/∂p
        let lanes = &mut bt.lanes[..m];
        Arch::new().dispatch(Kernel::Kappa {
            a: vcs,
            w: wjj,
            ra: rjj,
            p,
            out: lanes,
            sa: &mut bt.sal,
            sw: &mut bt.sw,
        });
        for k in 0..m {
            let mut s = [0.0; LANES];
            for (b, &c) in cs.iter().enumerate() {
                s[b] = ws.xi_p[j][k * 4 + c];
            }
            let col = &mut jx[k * n..k * n + m];
            for (x, kap) in col.iter_mut().zip(lanes.iter()) {
                *x -= s.iter().zip(kap).map(|(a, b)| a * b).sum::<f64>();
            }
        }
        // Λ_cᵀ p (−), a1 = ∂C_jcᵀ W_j p, d = V_c p − A A_cᵀ W p
        let lanes = &mut bt.lanes[..m];
        lanes.fill([0.0; LANES]);
        Arch::new().dispatch(Kernel::Phi {
            a: vcs,
            w: wjj,
            ra: rjj,
            p,
            upper: true,
            alpha: -1.0,
            out: lanes,
            sa: &mut bt.sal,
            sw: &mut bt.sw,
        });
        for (b, &c) in cs.iter().enumerate() {
            let dcj = &ws.dc[j][c];
            for (i, x) in bt.lp[b * m..(b + 1) * m].iter_mut().enumerate() {
                *x = lanes[i][b];
            }
            let a1 = &mut bt.a1[b * kk..(b + 1) * kk];
            gemv_t(a1, false, dcj, rjj, &ws.wp[o..o + rjj], 1.0);
            let d = &mut bt.d[b * r..(b + 1) * r];
            gemv_t(d, false, &ws.ta[j], kk, a1, -1.0);
            gemv(&mut d[o..o + rjj], true, dcj, rjj, &ws.eq[j], 1.0);
        }
        gemm(view_mut(&mut bt.gd, r, nc), false, view(&ws.g, r, r), view(&bt.d, r, nc), 1.0);
        // Z_c p = −Z Λ_cᵀp − Sᵀ(G d)_s − Σ_i E_iᵀ (C_iᵀ (G d)_i + [i = j] a1)
        gemm(view_mut(&mut bt.zc, na, nc), false, view(&ws.z, na, m), view(&bt.lp, m, nc), -1.0);
        gemm(
            view_mut(&mut bt.zc, na, nc),
            true,
            view(self.support_t_flat(), na, rs),
            view(&bt.gd, r, nc).subrows(0, rs),
            -1.0,
        );
        for (i, ir) in self.cons.joints.iter().enumerate() {
            let ki = ir.e.nrows();
            gemm(
                view_mut(&mut bt.cg, ki, nc),
                false,
                view(&ws.ct[i], ki, ir.rows),
                view(&bt.gd, r, nc).subrows(self.row_offsets[i], ir.rows),
                1.0,
            );
            if i == j {
                bt.cg[..ki * nc].iter_mut().zip(&bt.a1[..kk * nc]).for_each(|(x, y)| *x += y);
            }
            gemm(
                view_mut(&mut bt.zc, na, nc),
                true,
                view(self.e_t_flat(i), na, ki),
                view(&bt.cg, ki, nc),
                -1.0,
            );
        }
        // Z_cᵀ f1 + ZᵀJ11 Z_c p
        gemm(view_mut(&mut bt.colp, m, nc), false, view(&ws.t11, m, na), view(&bt.zc, na, nc), 1.0);
        let lanes = &mut bt.lanes[..m];
        lanes.fill([0.0; LANES]);
        let ztf = &ws.ztf;
        Arch::new().dispatch(Kernel::Phi {
            a: vcs,
            w: wjj,
            ra: rjj,
            p: ztf,
            upper: false,
            alpha: 1.0,
            out: lanes,
            sa: &mut bt.sal,
            sw: &mut bt.sw,
        });
        for (b, &c) in cs.iter().enumerate() {
            let (vc, dcj) = (&ws.vc[j][c], &ws.dc[j][c]);
            let colp = &mut bt.colp[b * m..(b + 1) * m];
            gemv_t(colp, true, vc, rjj, &ws.gf[o..o + rjj], -1.0);
            gemv(&mut ws.tj, false, dcj, rjj, &ws.epf[j], 1.0);
            gemv_t(colp, true, wjj, rjj, &ws.tj[..rjj], -1.0);
            colp.iter_mut().zip(lanes.iter()).for_each(|(x, l)| *x += l[b]);
        }
        // p2 rows, tracked rows
        // Z2ᵀJ21 (J21 itself, a view of the ambient Jacobian, when Z2 = I)
        let u21 = if self.z2_identity {
            let nf = na + self.basis.n2();
            view(&ws.jf, nf, nf).submatrix(na, 0, m2, na)
        } else {
            view(&ws.u21, m2, na)
        };
        gemm(view_mut(&mut bt.u2, m2, nc), false, u21, view(&bt.zc, na, nc), 1.0);
        for (t, tr) in self.tracked.iter().enumerate() {
            let nt = tr.rows.nrows();
            gemm(
                view_mut(&mut bt.eqc[t], nt, nc),
                false,
                view(&tr.rows_flat, nt, na),
                view(&bt.zc, na, nc),
                1.0,
            );
        }
        // ∂ξ̇ (all joints, root)
        for (i, map) in bt.maps.iter_mut().enumerate() {
            *map = RateMap::new(self, &ws.xi[i], true);
        }
        let root_map = root_xi.map(|xr| RateMap::new(self, &xr, false));
        for (b, &c) in cs.iter().enumerate() {
            let col = self.joint_offset(j) + c;
            jx[col * n + m..col * n + m + m2].copy_from_slice(&bt.u2[b * m2..(b + 1) * m2]);
            for (i, tr) in self.tracked.iter().take(nj).enumerate() {
                let nt = tr.rows.nrows();
                let mut d = bt.maps[i].apply(&bt.eqc[i][b * nt..(b + 1) * nt]);
                if i == j {
                    d += ws.mjs[j].column(c);
                }
                bt.dxd[b * nj + i] = d;
                let oi = self.joint_offset(i);
                jx[col * n + oi..col * n + oi + 4].copy_from_slice(d.as_slice());
            }
            if let Some(map) = &root_map {
                let kr = self.tracked[nj].rows.nrows();
                let d = map.apply(&bt.eqc[nj][b * kr..(b + 1) * kr]);
                let oi = self.root_offset();
                jx[col * n + oi..col * n + oi + 4].copy_from_slice(d.as_slice());
            }
        }
        // [∂V_c; ∂W_c] = Σ_i M_i (E_i Z): block c of M_i holds, on joint i's rows of ∂V,
        // ∂Ċ_i (from every ξ̇'s change and ∂²C/∂ξ_jc∂ξ_jd); for i = j also −ȦAᵀG[:, j] ∂C_jc
        // on all rows of ∂V and G[J, j] ∂C_jc on those of ∂W.
        let ld = LANES * q;
        for (i, ir) in self.cons.joints.iter().enumerate() {
            let (ri, ki, oi) = (ir.rows, ir.e.nrows(), self.row_offsets[i] - rs);
            let lm = &mut bt.lm[..ld * ki];
            lm.fill(0.0);
            for (b, &c) in cs.iter().enumerate() {
                let cd = &mut bt.cd[..ri * ki];
                cd.fill(0.0);
                for dd in 0..4 {
                    let s = bt.dxd[b * nj + i][dd];
                    cd.iter_mut().zip(&ws.dc[i][dd]).for_each(|(a, x)| *a += s * x);
                }
                if i == j {
                    for dd in 0..4 {
                        let s = ws.xi_dot[j][dd];
                        if s != 0.0 {
                            let c2 = &jr.c2[4 * c + dd];
                            cd.iter_mut().zip(c2.iter()).for_each(|(a, x)| *a += s * x);
                        }
                    }
                }
                for col in 0..ki {
                    for (s, x) in cd[col * ri..(col + 1) * ri].iter().enumerate() {
                        lm[col * ld + (oi + s) * LANES + b] = *x;
                    }
                }
                if i == j {
                    let dcj = &ws.dc[j][c];
                    for col in 0..ki {
                        let dcol = &dcj[col * rjj..(col + 1) * rjj];
                        let (lv, lw) = lm[col * ld..(col + 1) * ld].split_at_mut(rj * LANES);
                        for (k, &x) in dcol.iter().enumerate() {
                            if x == 0.0 {
                                continue;
                            }
                            let (adg_k, gj_k) = (
                                &ws.adat_g[k * rj..(k + 1) * rj],
                                &ws.g[(o + k) * r + rs..(o + k) * r + rs + rj],
                            );
                            for (v, a) in lv.chunks_exact_mut(LANES).zip(adg_k) {
                                v[b] -= a * x;
                            }
                            for (v, g) in lw.chunks_exact_mut(LANES).zip(gj_k) {
                                v[b] += g * x;
                            }
                        }
                    }
                }
            }
            gemm(
                view_mut(bt.dvw.as_flattened_mut(), ld, m),
                i > 0,
                view(lm, ld, ki),
                view(&ws.tz[i], ki, m),
                1.0,
            );
        }
        // X1 = ȦA_cᵀ − ȦAᵀ G A A_cᵀ (A A_cᵀ = (E_j Aᵀ)ᵀ ∂C_jcᵀ), all c side by side
        let w4 = nc * rjj;
        for (b, &c) in cs.iter().enumerate() {
            let dcj = &ws.dc[j][c];
            for s in 0..rjj {
                for col in 0..kk {
                    bt.dct[(b * rjj + s) * kk + col] = dcj[col * rjj + s];
                }
            }
        }
        gemm(
            view_mut(&mut bt.aac, r, w4),
            false,
            view(&ws.ta[j], kk, r).transpose(),
            view(&bt.dct, kk, w4),
            1.0,
        );
        gemm(view_mut(&mut bt.gaac, r, w4), false, view(&ws.g, r, r), view(&bt.aac, r, w4), 1.0);
        for (i, ir) in self.cons.joints.iter().enumerate() {
            let ki = ir.e.nrows();
            gemm(
                view_mut(&mut bt.x1tmp, ki, w4),
                false,
                view(&self.tracked[i].e[j], ki, kk),
                view(&bt.dct, kk, w4),
                1.0,
            );
            gemm(
                view_mut(&mut bt.x1, rj, w4).subrows_mut(self.row_offsets[i] - rs, ir.rows),
                false,
                view(&ws.cdot[i], ir.rows, ki),
                view(&bt.x1tmp, ki, w4),
                1.0,
            );
        }
        gemm(
            view_mut(&mut bt.x1, rj, w4),
            true,
            view(&ws.adat, rj, r),
            view(&bt.gaac, r, w4),
            -1.0,
        );
        // [∂V_c; ∂W_c] −= [X1_c; G A A_cᵀ (rows J)] W_j
        {
            let rm = &mut bt.rm[..ld * rjj];
            rm.fill(0.0);
            for b in 0..nc {
                for k in 0..rjj {
                    let cidx = b * rjj + k;
                    let base = k * ld + b;
                    for s in 0..rj {
                        rm[base + s * LANES] = bt.x1[cidx * rj + s];
                        rm[base + (rj + s) * LANES] = bt.gaac[cidx * r + rs + s];
                    }
                }
            }
            gemm(
                view_mut(bt.dvw.as_flattened_mut(), ld, m),
                true,
                view(rm, ld, rjj),
                view(wjj, rjj, m),
                -1.0,
            );
        }
        // − [V; W_J] Λ_cᵀ, − ∂(K p)
        let (dvw, pvw) = (&mut bt.dvw[..q * m], &bt.pvw);
        Arch::new().dispatch(Kernel::RightPhi {
            pm: pvw,
            q,
            a: vcs,
            w: wjj,
            ra: rjj,
            m,
            out: dvw,
            s1: &mut bt.s1,
            s2: &mut bt.s2,
            dl: &mut bt.lanes,
        });
        let t = &mut bt.lanes[..m];
        Arch::new().dispatch(Kernel::Skew { dvw, pvw, rj, p, t, sd: &mut bt.sd, sv: &mut bt.sv });
        for (b, &c) in cs.iter().enumerate() {
            let col = self.joint_offset(j) + c;
            for i in 0..m {
                jx[col * n + i] = bt.colp[b * m + i] - t[i][b];
            }
        }
    }
}
