//! Dense kernels of the null-space frame `Z(ξ)` (theory.md §10.4): column-major buffers viewed
//! as faer matrices, Cholesky (faer's in-place `llt`), triangular solves and products, and the
//! O(r·m) forms of the skew `K` and of the Cholesky-derivative triangle `Φ`.
//!
//! With `M = aᵀb` (`a`, `b` of `r` rows, `m` columns), `K(a, b) = strictly upper(Mᵀ) − strictly
//! lower(M)` is the skew matrix `−M − Φ(−(M + Mᵀ))ᵀ` of theory.md §10.4 (`K = −VᵀW − Λᵀ`,
//! `Λ = Φ(X)`, `X = −(WᵀV + VᵀW)`), and `Φ(aᵀb + bᵀa)` is a triangle of inner products; both
//! act on a vector by running sums of columns instead of forming the `m × m` matrix.

use crate::error::{ModalError, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
use faer::linalg::matmul::matmul;
use faer::traits::pulp::{Arch, Simd, WithSimd};
use faer::{Accum, MatMut, MatRef, Par};

/// `match n { 1 => f::<1>(args), …, 6 => f::<6>(args), _ => fallback }`: a small run-time size
/// (a joint's row count) as a compile-time constant, so a kernel's running sums stay in
/// registers; larger sizes take `fallback`.
macro_rules! small_size {
    ($n:expr, $f:ident($($arg:expr),* $(,)?), $fallback:expr) => {
        match $n {
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            3 => $f::<3>($($arg),*),
            4 => $f::<4>($($arg),*),
            5 => $f::<5>($($arg),*),
            6 => $f::<6>($($arg),*),
            _ => $fallback,
        }
    };
}
pub(crate) use small_size;

/// `r × c` column-major view of `d`.
pub(crate) fn view(d: &[f64], r: usize, c: usize) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(&d[..r * c], r, c)
}

/// `r × c` column-major mutable view of `d`.
pub(crate) fn view_mut(d: &mut [f64], r: usize, c: usize) -> MatMut<'_, f64> {
    MatMut::from_column_major_slice_mut(&mut d[..r * c], r, c)
}

/// `dst (+)= alpha · a b`.
pub(crate) fn gemm(
    dst: MatMut<'_, f64>,
    add: bool,
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    alpha: f64,
) {
    if dst.nrows() == 0 || dst.ncols() == 0 {
        return;
    }
    if a.ncols() == 0 {
        if !add {
            let mut dst = dst;
            dst.fill(0.0);
        }
        return;
    }
    matmul(dst, if add { Accum::Add } else { Accum::Replace }, a, b, alpha, Par::Seq);
}

/// `y (+)= alpha · a x` for column-major `a` (`r × c`): from 64 entries by the vector-lane
/// [`matvec`], below by plain column loops (a few entries do not pay for the dispatch).
pub(crate) fn gemv(y: &mut [f64], add: bool, a: &[f64], r: usize, x: &[f64], alpha: f64) {
    if r * x.len() >= 64 {
        matvec(&mut y[..r], add, &a[..r * x.len()], x, alpha);
        return;
    }
    if !add {
        y[..r].fill(0.0);
    }
    for (j, &xj) in x.iter().enumerate() {
        let s = alpha * xj;
        if s != 0.0 {
            y[..r].iter_mut().zip(&a[j * r..(j + 1) * r]).for_each(|(y, a)| *y += s * a);
        }
    }
}

/// `y (+)= alpha · aᵀ x` for column-major `a` (`r × c`, `x` of length `r`): from 64 entries
/// four columns at a time in vector lanes, below by plain dot products.
pub(crate) fn gemv_t(y: &mut [f64], add: bool, a: &[f64], r: usize, x: &[f64], alpha: f64) {
    if r * y.len() >= 64 {
        Arch::new().dispatch(ColumnDots { y, add, a, r, x: &x[..r], alpha });
        return;
    }
    for (j, y) in y.iter_mut().enumerate() {
        let d: f64 = a[j * r..(j + 1) * r].iter().zip(x).map(|(a, x)| a * x).sum();
        *y = if add { *y + alpha * d } else { alpha * d };
    }
}

/// Lower Cholesky factor of the symmetric `n × n` matrix in `a`, in place (strict upper
/// triangle zeroed). Errors when a pivot `L_jj²` is not above `tol · max_i a_ii` (relative) or
/// `tol` (when `relative` is false).
pub(crate) fn cholesky(
    a: &mut [f64],
    n: usize,
    tol: f64,
    relative: bool,
    stage: &str,
    reason: &str,
) -> Result<()> {
    let scale = if relative { (0..n).fold(0.0f64, |m, i| m.max(a[i * n + i])) } else { 1.0 };
    let fail = || ModalError::Numerical { stage: stage.to_string(), reason: reason.to_string() };
    if n == 0 {
        return Ok(());
    }
    let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(n, Par::Seq, Default::default()));
    let stack = MemStack::new(&mut mem);
    cholesky_in_place(view_mut(a, n, n), Default::default(), Par::Seq, stack, Default::default())
        .map_err(|_| fail())?;
    for j in 0..n {
        let d = a[j * n + j];
        if d.is_nan() || d * d <= tol * scale {
            return Err(fail());
        }
        a[j * n..j * n + j].fill(0.0);
    }
    Ok(())
}

/// `out (+)= K(a, b) p` with `K(a, b)_il = a_lᵀb_i (l > i)`, `−a_iᵀb_l (l < i)`, `0 (l = i)`
/// (module docs): `out_i = b_iᵀ Σ_{l>i} p_l a_l − a_iᵀ Σ_{l<i} p_l b_l`. `a`, `b`: `r × m`
/// column-major; `tmp`: `r` scratch.
pub(crate) fn skew_apply(
    a: &[f64],
    b: &[f64],
    r: usize,
    p: &[f64],
    out: &mut [f64],
    tmp: &mut [f64],
) {
    Arch::new().dispatch(SkewApply { a, b, r, p, out, tmp });
}

/// [`skew_apply`] under the run-time dispatch, `r ≤ 6` as a constant (the running sums in
/// registers; the same sums in the same order).
struct SkewApply<'a> {
    a: &'a [f64],
    b: &'a [f64],
    r: usize,
    p: &'a [f64],
    out: &'a mut [f64],
    tmp: &'a mut [f64],
}

impl WithSimd for SkewApply<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let SkewApply { a, b, r, p, out, tmp } = self;
        small_size!(r, skew_apply_const(a, b, p, out), skew_apply_imp(a, b, r, p, out, tmp))
    }
}

#[inline(always)]
fn skew_apply_const<const R: usize>(a: &[f64], b: &[f64], p: &[f64], out: &mut [f64]) {
    let mut tmp = [0.0; R];
    skew_apply_imp(a, b, R, p, out, &mut tmp)
}

#[inline(always)]
fn skew_apply_imp(a: &[f64], b: &[f64], r: usize, p: &[f64], out: &mut [f64], tmp: &mut [f64]) {
    let m = p.len();
    let tmp = &mut tmp[..r];
    // suffix sums of p_l a_l
    tmp.fill(0.0);
    for i in (0..m).rev() {
        let bi = &b[i * r..(i + 1) * r];
        out[i] += bi.iter().zip(tmp.iter()).map(|(x, y)| x * y).sum::<f64>();
        let ai = &a[i * r..(i + 1) * r];
        tmp.iter_mut().zip(ai).for_each(|(t, x)| *t += p[i] * x);
    }
    tmp.fill(0.0);
    for i in 0..m {
        let ai = &a[i * r..(i + 1) * r];
        out[i] -= ai.iter().zip(tmp.iter()).map(|(x, y)| x * y).sum::<f64>();
        let bi = &b[i * r..(i + 1) * r];
        tmp.iter_mut().zip(bi).for_each(|(t, x)| *t += p[i] * x);
    }
}

/// The lower Cholesky factor `L` of `S = I − YᵀY` (`Y`: `q × m`, `q` small) in generator form
/// `L = diag(d) − strictly lower(Yᵀ Hᵀ…)`, i.e. `L_ij = −y_iᵀ h_j` (`i > j`), `L_jj = d_j`:
/// eliminating column `j` of `I − Y_ᵀ M Y` (`M = I` at first) leaves `I − Yᵀ(M + h_j h_jᵀ)Y`
/// with `g = M y_j`, `d_j² = 1 − y_jᵀ g`, `h_j = g / d_j`: `O(m q²)` instead of `O(m³)`, the same
/// factor (Cholesky factors are unique). `h`: `q × m`; `mm`: `q × q` and `g`: `q` scratch.
/// Errors when a pivot `d_j²` is not above `tol`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn lowrank_cholesky(
    y: &[f64],
    q: usize,
    m: usize,
    d: &mut [f64],
    h: &mut [f64],
    mm: &mut [f64],
    g: &mut [f64],
    tol: f64,
    stage: &str,
    reason: &str,
) -> Result<()> {
    let ok = Arch::new().dispatch(LowrankCholesky { y, q, m, d, h, mm, g, tol });
    if ok {
        Ok(())
    } else {
        Err(ModalError::Numerical { stage: stage.to_string(), reason: reason.to_string() })
    }
}

/// [`lowrank_cholesky`] under the run-time dispatch: `q ≤ 6` as a constant in the prefix-sum
/// form ([`lowrank_cholesky_const`]), larger `q` by the recurrence. `false` when a pivot fails.
struct LowrankCholesky<'a> {
    y: &'a [f64],
    q: usize,
    m: usize,
    d: &'a mut [f64],
    h: &'a mut [f64],
    mm: &'a mut [f64],
    g: &'a mut [f64],
    tol: f64,
}

impl WithSimd for LowrankCholesky<'_> {
    type Output = bool;

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> bool {
        let LowrankCholesky { y, q, m, d, h, mm, g, tol } = self;
        small_size!(
            q,
            lowrank_cholesky_const(y, m, d, h, tol),
            lowrank_cholesky_imp(y, q, m, d, h, mm, g, tol)
        )
    }
}

/// [`lowrank_cholesky`] for `q = Q ≤ 6`, with the elimination's recurrence reduced to prefix
/// sums: by Sherman–Morrison the `M` of step `j` is `N_j⁻¹` with `N_j = I − Σ_{i<j} y_i y_iᵀ`
/// (`q × q`), so `g = N_j⁻¹ y_j` (a `q × q` `LDLᵀ` solve), `d_j² = 1 − y_jᵀ g`,
/// `h_j = g / d_j`. The only dependence from one column to the next is the update of `N`, so
/// the divisions and square roots of different columns overlap (the same factor to round-off
/// as [`lowrank_cholesky_imp`]).
#[inline(always)]
fn lowrank_cholesky_const<const Q: usize>(
    y: &[f64],
    m: usize,
    d: &mut [f64],
    h: &mut [f64],
    tol: f64,
) -> bool {
    let mut nn = [[0.0f64; Q]; Q];
    for (k, row) in nn.iter_mut().enumerate() {
        row[k] = 1.0;
    }
    for j in 0..m {
        let yj: &[f64; Q] = y[j * Q..(j + 1) * Q].try_into().expect("column");
        // LDLᵀ of N_j (lower triangle of `l`, pivots in `dd`), then g = N_j⁻¹ y_j
        // (pivots kept as reciprocals: one division per pivot)
        let (mut l, mut dd, mut rd) = ([[0.0f64; Q]; Q], [0.0f64; Q], [0.0f64; Q]);
        for k in 0..Q {
            let mut dk = nn[k][k];
            for i in 0..k {
                dk -= l[k][i] * l[k][i] * dd[i];
            }
            dd[k] = dk;
            rd[k] = 1.0 / dk;
            for r in k + 1..Q {
                let mut v = nn[r][k];
                for i in 0..k {
                    v -= l[r][i] * l[k][i] * dd[i];
                }
                l[r][k] = v * rd[k];
            }
        }
        let mut g = *yj;
        for k in 0..Q {
            for i in 0..k {
                g[k] -= l[k][i] * g[i];
            }
        }
        for k in 0..Q {
            g[k] *= rd[k];
        }
        for k in (0..Q).rev() {
            for r in k + 1..Q {
                g[k] -= l[r][k] * g[r];
            }
        }
        let d2 = 1.0 - (0..Q).map(|k| yj[k] * g[k]).sum::<f64>();
        if d2.is_nan() || d2 <= tol {
            return false;
        }
        let dj = d2.sqrt();
        d[j] = dj;
        let rj = 1.0 / dj;
        for k in 0..Q {
            h[j * Q + k] = g[k] * rj;
        }
        for a in 0..Q {
            for b in 0..Q {
                nn[a][b] -= yj[a] * yj[b];
            }
        }
    }
    true
}

/// The elimination of [`lowrank_cholesky`] for `q > 6`; `M q`-products as [`gemv`]'s plain
/// loops below 64 entries.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn lowrank_cholesky_imp(
    y: &[f64],
    q: usize,
    m: usize,
    d: &mut [f64],
    h: &mut [f64],
    mm: &mut [f64],
    g: &mut [f64],
    tol: f64,
) -> bool {
    let (mm, g) = (&mut mm[..q * q], &mut g[..q]);
    mm.fill(0.0);
    for k in 0..q {
        mm[k * q + k] = 1.0;
    }
    for j in 0..m {
        let yj = &y[j * q..(j + 1) * q];
        if q * q >= 64 {
            gemv(g, false, mm, q, yj, 1.0);
        } else {
            g.fill(0.0);
            for (c, &s) in yj.iter().enumerate() {
                if s != 0.0 {
                    g.iter_mut().zip(&mm[c * q..(c + 1) * q]).for_each(|(y, a)| *y += s * a);
                }
            }
        }
        let d2 = 1.0 - yj.iter().zip(g.iter()).map(|(a, b)| a * b).sum::<f64>();
        if d2.is_nan() || d2 <= tol {
            return false;
        }
        let dj = d2.sqrt();
        d[j] = dj;
        let hj = &mut h[j * q..(j + 1) * q];
        hj.iter_mut().zip(g.iter()).for_each(|(h, g)| *h = g / dj);
        for c in 0..q {
            let s = hj[c];
            mm[c * q..(c + 1) * q].iter_mut().zip(hj.iter()).for_each(|(a, b)| *a += s * b);
        }
    }
    true
}

/// `X ← X L⁻ᵀ` for each `X` of `xs` (`rows × m`, column-major) and `L` of
/// [`lowrank_cholesky`]: column `i` of `X Lᵀ` is `d_i X_i − (Σ_{j<i} X_j h_jᵀ) y_i`, so
/// `X_i = (M_i + A y_i) / d_i` with the running sum `A = Σ_{j<i} X_j h_jᵀ` (`rows × q`, scratch
/// `acc` of `Σ rows · q`): `O(rows m q)`. All matrices advance together column by column, so
/// the latency of one matrix's recurrence is hidden by the others' work.
#[inline(always)]
fn lowrank_right_solve_lt_imp(
    y: &[f64],
    h: &[f64],
    d: &[f64],
    q: usize,
    xs: &mut [(&mut [f64], usize)],
    acc: &mut [f64],
) {
    let total: usize = xs.iter().map(|(_, rows)| rows).sum();
    acc[..total * q].fill(0.0);
    for (i, &di) in d.iter().enumerate() {
        let (yi, hi) = (&y[i * q..(i + 1) * q], &h[i * q..(i + 1) * q]);
        let inv = 1.0 / di;
        let mut off = 0;
        for (x, rows) in xs.iter_mut() {
            let rows = *rows;
            let acc = &mut acc[off * q..(off + rows) * q];
            off += rows;
            let xi = &mut x[i * rows..(i + 1) * rows];
            // rows in chunks of four (one vector), each row's value kept while the q terms
            // are added
            let full = rows / 4 * 4;
            for c in (0..full).step_by(4) {
                let mut v = [xi[c], xi[c + 1], xi[c + 2], xi[c + 3]];
                for k in 0..q {
                    let a = &acc[k * rows + c..k * rows + c + 4];
                    for e in 0..4 {
                        v[e] = yi[k].mul_add(a[e], v[e]);
                    }
                }
                for e in &mut v {
                    *e *= inv;
                }
                xi[c..c + 4].copy_from_slice(&v);
                for k in 0..q {
                    let a = &mut acc[k * rows + c..k * rows + c + 4];
                    for e in 0..4 {
                        a[e] = hi[k].mul_add(v[e], a[e]);
                    }
                }
            }
            for c in full..rows {
                let mut v = xi[c];
                for k in 0..q {
                    v = yi[k].mul_add(acc[k * rows + c], v);
                }
                v *= inv;
                xi[c] = v;
                for k in 0..q {
                    acc[k * rows + c] = hi[k].mul_add(v, acc[k * rows + c]);
                }
            }
        }
    }
}

struct RightSolve<'a, 'b> {
    y: &'a [f64],
    h: &'a [f64],
    d: &'a [f64],
    q: usize,
    xs: &'a mut [(&'b mut [f64], usize)],
    acc: &'a mut [f64],
}

impl WithSimd for RightSolve<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let RightSolve { y, h, d, q, xs, acc } = self;
        // `q` as a constant: the `q` terms of each step unrolled, `y_i`, `h_i` in registers
        small_size!(
            q,
            lowrank_right_solve_lt_const(y, h, d, xs, acc),
            lowrank_right_solve_lt_imp(y, h, d, q, xs, acc)
        )
    }
}

/// [`lowrank_right_solve_lt_imp`] with `q = Q`.
#[inline(always)]
fn lowrank_right_solve_lt_const<const Q: usize>(
    y: &[f64],
    h: &[f64],
    d: &[f64],
    xs: &mut [(&mut [f64], usize)],
    acc: &mut [f64],
) {
    lowrank_right_solve_lt_imp(y, h, d, Q, xs, acc)
}

/// [`lowrank_right_solve_lt_imp`] compiled for the processor's vector instructions.
pub(crate) fn lowrank_right_solve_lt(
    y: &[f64],
    h: &[f64],
    d: &[f64],
    q: usize,
    xs: &mut [(&mut [f64], usize)],
    acc: &mut [f64],
) {
    if xs.iter().all(|(_, rows)| *rows == 0) {
        return;
    }
    Arch::new().dispatch(RightSolve { y, h, d, q, xs, acc });
}

/// `t ← L⁻¹ t` (forward: `t_i = (t_i + y_iᵀ a) / d_i`, `a += h_i t_i`) with `L` of
/// [`lowrank_cholesky`]; `a`: `q` scratch.
pub(crate) fn lowrank_solve_l(
    y: &[f64],
    h: &[f64],
    d: &[f64],
    q: usize,
    t: &mut [f64],
    a: &mut [f64],
) {
    Arch::new().dispatch(Sweep { g: y, e: h, d, q, t, a, forward: true });
}

/// `t ← L⁻ᵀ t` (backward: `t_j = (t_j + h_jᵀ a) / d_j`, `a += y_j t_j`) with `L` of
/// [`lowrank_cholesky`]; `a`: `q` scratch.
pub(crate) fn lowrank_solve_lt(
    y: &[f64],
    h: &[f64],
    d: &[f64],
    q: usize,
    t: &mut [f64],
    a: &mut [f64],
) {
    Arch::new().dispatch(Sweep { g: h, e: y, d, q, t, a, forward: false });
}

/// [`lowrank_sweep`] under the run-time dispatch, `q ≤ 6` as a constant (the running sums in
/// registers; the same sums in the same order).
struct Sweep<'a> {
    g: &'a [f64],
    e: &'a [f64],
    d: &'a [f64],
    q: usize,
    t: &'a mut [f64],
    a: &'a mut [f64],
    forward: bool,
}

impl WithSimd for Sweep<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let Sweep { g, e, d, q, t, a, forward } = self;
        small_size!(
            q,
            sweep_const(g, e, d, t, forward),
            if forward {
                lowrank_sweep(g, e, d, q, t, a, 0..d.len())
            } else {
                lowrank_sweep(g, e, d, q, t, a, (0..d.len()).rev())
            }
        )
    }
}

#[inline(always)]
fn sweep_const<const Q: usize>(g: &[f64], e: &[f64], d: &[f64], t: &mut [f64], forward: bool) {
    let mut a = [0.0; Q];
    if forward {
        lowrank_sweep(g, e, d, Q, t, &mut a, 0..d.len())
    } else {
        lowrank_sweep(g, e, d, Q, t, &mut a, (0..d.len()).rev())
    }
}

/// The triangular sweep of both solves: for `i` in `order`, `t_i = (t_i + g_iᵀ a) / d_i`,
/// then `a += e_i t_i` (`g`, `e`: `q` entries per row).
#[inline(always)]
fn lowrank_sweep(
    g: &[f64],
    e: &[f64],
    d: &[f64],
    q: usize,
    t: &mut [f64],
    a: &mut [f64],
    order: impl Iterator<Item = usize>,
) {
    let a = &mut a[..q];
    a.fill(0.0);
    for i in order {
        let (gi, ei) = (&g[i * q..(i + 1) * q], &e[i * q..(i + 1) * q]);
        let ti = (t[i] + gi.iter().zip(a.iter()).map(|(x, y)| x * y).sum::<f64>()) / d[i];
        t[i] = ti;
        a.iter_mut().zip(ei).for_each(|(a, e)| *a += e * ti);
    }
}

/// `out (+)= alpha · g x` for column-major `g` (`out.len() × x.len()`), by blocks of rows held
/// in vector registers across all columns (each entry of `g` loaded once, `out` stored once;
/// eight independent accumulators per block cover the latency of the fused multiply–adds),
/// compiled for the processor's vector instructions by pulp's run-time dispatch.
pub(crate) fn matvec(out: &mut [f64], add: bool, g: &[f64], x: &[f64], alpha: f64) {
    Arch::new().dispatch(RowBlockMatvec { out, add, g, x, alpha });
}

struct RowBlockMatvec<'a> {
    out: &'a mut [f64],
    add: bool,
    g: &'a [f64],
    x: &'a [f64],
    alpha: f64,
}

impl WithSimd for RowBlockMatvec<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let RowBlockMatvec { out, add, g, x, alpha } = self;
        let rows = out.len();
        let mut r0 = 0;
        r0 = row_blocks::<32>(out, add, g, x, alpha, rows, r0);
        r0 = row_blocks::<16>(out, add, g, x, alpha, rows, r0);
        r0 = row_blocks::<8>(out, add, g, x, alpha, rows, r0);
        r0 = row_blocks::<4>(out, add, g, x, alpha, rows, r0);
        row_blocks::<1>(out, add, g, x, alpha, rows, r0);
    }
}

/// Rows `r0..` of [`RowBlockMatvec`] in blocks of `B` while a whole block fits; returns the
/// first row not done.
#[inline(always)]
fn row_blocks<const B: usize>(
    out: &mut [f64],
    add: bool,
    g: &[f64],
    x: &[f64],
    alpha: f64,
    rows: usize,
    mut r0: usize,
) -> usize {
    while r0 + B <= rows {
        let mut acc = [0.0; B];
        for (l, &xl) in x.iter().enumerate() {
            let c: &[f64; B] = g[l * rows + r0..l * rows + r0 + B].try_into().expect("block");
            for e in 0..B {
                acc[e] = xl.mul_add(c[e], acc[e]);
            }
        }
        let o = &mut out[r0..r0 + B];
        if add {
            o.iter_mut().zip(&acc).for_each(|(o, a)| *o = alpha.mul_add(*a, *o));
        } else if alpha == 1.0 {
            o.copy_from_slice(&acc);
        } else {
            o.iter_mut().zip(&acc).for_each(|(o, a)| *o = alpha * a);
        }
        r0 += B;
    }
    r0
}

/// `y (+)= alpha · aᵀ x` ([`gemv_t`]) four columns at a time: the dot products run along the
/// rows in vector lanes (`x` loaded once per four columns), reduced across lanes at the end.
struct ColumnDots<'a> {
    y: &'a mut [f64],
    add: bool,
    a: &'a [f64],
    r: usize,
    x: &'a [f64],
    alpha: f64,
}

impl WithSimd for ColumnDots<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let ColumnDots { y, add, a, r, x, alpha } = self;
        column_dots(y, add, a, r, x, alpha);
    }
}

/// The body of [`ColumnDots`].
#[inline(always)]
fn column_dots(y: &mut [f64], add: bool, a: &[f64], r: usize, x: &[f64], alpha: f64) {
    let full = r / 4 * 4;
    let put = |y: &mut f64, d: f64| *y = if add { alpha.mul_add(d, *y) } else { alpha * d };
    let lane_sum = |v: [f64; 4]| (v[0] + v[1]) + (v[2] + v[3]);
    let c4 = y.len() / 4 * 4;
    for j in (0..c4).step_by(4) {
        let cols: [&[f64]; 4] = std::array::from_fn(|b| &a[(j + b) * r..(j + b + 1) * r]);
        let mut acc = [[0.0f64; 4]; 4];
        for i in (0..full).step_by(4) {
            let xv: &[f64; 4] = x[i..i + 4].try_into().expect("chunk");
            for b in 0..4 {
                let cv: &[f64; 4] = cols[b][i..i + 4].try_into().expect("chunk");
                for e in 0..4 {
                    acc[b][e] = cv[e].mul_add(xv[e], acc[b][e]);
                }
            }
        }
        for b in 0..4 {
            let mut d = lane_sum(acc[b]);
            for i in full..r {
                d = cols[b][i].mul_add(x[i], d);
            }
            put(&mut y[j + b], d);
        }
    }
    for j in c4..y.len() {
        let col = &a[j * r..(j + 1) * r];
        let mut acc = [0.0f64; 4];
        for i in (0..full).step_by(4) {
            for e in 0..4 {
                acc[e] = col[i + e].mul_add(x[i + e], acc[e]);
            }
        }
        let mut d = lane_sum(acc);
        for i in full..r {
            d = col[i].mul_add(x[i], d);
        }
        put(&mut y[j], d);
    }
}

/// `out = g x` for column-major `g` (`rows × k`) and `x` (`k × cols`, column stride `ldx`) into
/// the first `rows` entries of `cols` columns of `out` (column stride `ldo`), under one run-time
/// dispatch: two columns at a time, rows in blocks of sixteen, eight and four (up to eight
/// independent accumulator vectors across the `k` fused multiply–adds).
#[allow(clippy::too_many_arguments)]
pub(crate) fn matmul_nn(
    out: &mut [f64],
    ldo: usize,
    g: &[f64],
    rows: usize,
    x: &[f64],
    ldx: usize,
    k: usize,
    cols: usize,
) {
    Arch::new().dispatch(MatmulNn { out, ldo, g, rows, x, ldx, k, cols });
}

struct MatmulNn<'a> {
    out: &'a mut [f64],
    ldo: usize,
    g: &'a [f64],
    rows: usize,
    x: &'a [f64],
    ldx: usize,
    k: usize,
    cols: usize,
}

impl WithSimd for MatmulNn<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let MatmulNn { out, ldo, g, rows, x, ldx, k, cols } = self;
        let g = &g[..rows * k];
        let mut j = 0;
        while j + 2 <= cols {
            let (x0, x1) = (&x[j * ldx..j * ldx + k], &x[(j + 1) * ldx..(j + 1) * ldx + k]);
            let (o0, o1) = out[j * ldo..(j + 1) * ldo + rows].split_at_mut(ldo);
            let (o0, o1) = (&mut o0[..rows], &mut o1[..rows]);
            let mut r0 = 0;
            r0 = nn_blocks2::<16>(o0, o1, g, rows, x0, x1, r0);
            r0 = nn_blocks2::<8>(o0, o1, g, rows, x0, x1, r0);
            r0 = nn_blocks2::<4>(o0, o1, g, rows, x0, x1, r0);
            nn_blocks2::<1>(o0, o1, g, rows, x0, x1, r0);
            j += 2;
        }
        if j < cols {
            let x0 = &x[j * ldx..j * ldx + k];
            let o = &mut out[j * ldo..j * ldo + rows];
            let r0 = row_blocks::<16>(o, false, g, x0, 1.0, rows, 0);
            let r0 = row_blocks::<4>(o, false, g, x0, 1.0, rows, r0);
            row_blocks::<1>(o, false, g, x0, 1.0, rows, r0);
        }
    }
}

/// Rows `r0..` of two columns of [`MatmulNn`] in blocks of `B`; returns the first row not done.
#[inline(always)]
fn nn_blocks2<const B: usize>(
    o0: &mut [f64],
    o1: &mut [f64],
    g: &[f64],
    rows: usize,
    x0: &[f64],
    x1: &[f64],
    mut r0: usize,
) -> usize {
    while r0 + B <= rows {
        let (mut a0, mut a1) = ([0.0; B], [0.0; B]);
        for (l, (&y0, &y1)) in x0.iter().zip(x1).enumerate() {
            let c: &[f64; B] = g[l * rows + r0..l * rows + r0 + B].try_into().expect("block");
            for e in 0..B {
                a0[e] = y0.mul_add(c[e], a0[e]);
                a1[e] = y1.mul_add(c[e], a1[e]);
            }
        }
        o0[r0..r0 + B].copy_from_slice(&a0);
        o1[r0..r0 + B].copy_from_slice(&a1);
        r0 += B;
    }
    r0
}

/// `out[:, j] = aᵀ b[:, j]` for column-major `a` (`r × c`) and the columns of `b` (`r` rows,
/// column stride `ldb`) into the columns of `out` (`c` rows from each column's start, stride
/// `ldo`), under one run-time dispatch ([`gemv_t`]'s four-column dot products).
pub(crate) fn matmul_tn(
    out: &mut [f64],
    ldo: usize,
    a: &[f64],
    r: usize,
    b: &[f64],
    ldb: usize,
    cols: usize,
) {
    Arch::new().dispatch(MatmulTn { out, ldo, a, r, b, ldb, cols });
}

struct MatmulTn<'a> {
    out: &'a mut [f64],
    ldo: usize,
    a: &'a [f64],
    r: usize,
    b: &'a [f64],
    ldb: usize,
    cols: usize,
}

impl WithSimd for MatmulTn<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let MatmulTn { out, ldo, a, r, b, ldb, cols } = self;
        let c = a.len().checked_div(r).unwrap_or(0);
        for j in 0..cols {
            let y = &mut out[j * ldo..j * ldo + c];
            column_dots(y, false, a, r, &b[j * ldb..j * ldb + r], 1.0);
        }
    }
}
