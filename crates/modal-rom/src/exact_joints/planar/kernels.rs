//! Register kernels of the planar evaluation (module docs of [`super`]): small products and
//! the low-rank frame factor and right solve of [`crate::exact_joints::frame`] in forms whose
//! running sums stay in registers or whose columns do not wait on each other (theory.md §10.4,
//! §10.9).

use crate::error::{ModalError, Result};
use crate::exact_joints::frame::{gemv, lowrank_cholesky, small_size};
use faer::traits::pulp::{Arch, Simd, WithSimd};

/// [`gemv`] for a small row count `r ≤ 6` (below its 64 entries) with the `r` sums in a local
/// array of constant length (registers) instead of the output slice (each column's update
/// otherwise waits for the previous one's store); the same sums in the same order. Other
/// sizes take [`gemv`].
pub(crate) fn gemv_small(y: &mut [f64], add: bool, a: &[f64], r: usize, x: &[f64], alpha: f64) {
    if r * x.len() >= 64 {
        return gemv(y, add, a, r, x, alpha);
    }
    small_size!(r, gemv_const(y, add, a, x, alpha), gemv(y, add, a, r, x, alpha))
}

#[inline(always)]
fn gemv_const<const R: usize>(y: &mut [f64], add: bool, a: &[f64], x: &[f64], alpha: f64) {
    let y: &mut [f64; R] = (&mut y[..R]).try_into().expect("rows");
    let mut acc = if add { *y } else { [0.0; R] };
    for (j, &xj) in x.iter().enumerate() {
        let s = alpha * xj;
        if s != 0.0 {
            let c: &[f64; R] = a[j * R..(j + 1) * R].try_into().expect("column");
            for e in 0..R {
                acc[e] += s * c[e];
            }
        }
    }
    *y = acc;
}

/// [`lowrank_cholesky`]'s factor with the elimination's recurrence reduced to prefix sums: by
/// Sherman–Morrison the `M` of step `j` is `N_j⁻¹` with `N_j = I − Σ_{i<j} y_i y_iᵀ` (`q × q`),
/// so `g = N_j⁻¹ y_j` (a `q × q` `LDLᵀ` solve), `d_j² = 1 − y_jᵀ g`, `h_j = g / d_j`: the only
/// dependence from one column to the next is the update of `N`, and the divisions and square
/// roots of different columns overlap (the same factor to round-off). For `q ≤ 6`; larger `q`
/// take [`lowrank_cholesky`].
#[allow(clippy::too_many_arguments)]
pub(crate) fn lowrank_cholesky_prefix(
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
    if q > 6 {
        return lowrank_cholesky(y, q, m, d, h, mm, g, tol, stage, reason);
    }
    let ok = Arch::new().dispatch(LowrankPrefix { y, q, m, d, h, tol });
    if ok {
        Ok(())
    } else {
        Err(ModalError::Numerical { stage: stage.to_string(), reason: reason.to_string() })
    }
}

struct LowrankPrefix<'a> {
    y: &'a [f64],
    q: usize,
    m: usize,
    d: &'a mut [f64],
    h: &'a mut [f64],
    tol: f64,
}

impl WithSimd for LowrankPrefix<'_> {
    type Output = bool;

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> bool {
        let LowrankPrefix { y, q, m, d, h, tol } = self;
        small_size!(q, lowrank_prefix_const(y, m, d, h, tol), false)
    }
}

/// The body of [`lowrank_cholesky_prefix`] for `q = Q`.
#[inline(always)]
fn lowrank_prefix_const<const Q: usize>(
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

/// [`crate::exact_joints::frame::lowrank_right_solve_lt`] for one matrix whose row count `rows` is a multiple of four
/// (callers pad with zero rows), `q ≤ 6`: blocks of up to sixteen rows advance through all `m`
/// columns with their running sums `A` in registers (the general kernel keeps them in `acc`,
/// so each column's update waits for the previous column's store), and the `1 / d_i` are formed
/// once (`rinv`: `m` scratch). The same operations in the same order per row: the same bits.
pub(crate) fn lowrank_right_solve_lt_padded(
    y: &[f64],
    h: &[f64],
    d: &[f64],
    q: usize,
    x: &mut [f64],
    rows: usize,
    rinv: &mut [f64],
) {
    debug_assert!(rows % 4 == 0 && q <= 6);
    Arch::new().dispatch(PaddedSolve { y, h, d, q, x, rows, rinv });
}

struct PaddedSolve<'a> {
    y: &'a [f64],
    h: &'a [f64],
    d: &'a [f64],
    q: usize,
    x: &'a mut [f64],
    rows: usize,
    rinv: &'a mut [f64],
}

impl WithSimd for PaddedSolve<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let PaddedSolve { y, h, d, q, x, rows, rinv } = self;
        let rinv = &mut rinv[..d.len()];
        rinv.iter_mut().zip(d).for_each(|(r, d)| *r = 1.0 / d);
        small_size!(q, padded_solve_const(y, h, rinv, x, rows), ())
    }
}

#[inline(always)]
fn padded_solve_const<const Q: usize>(
    y: &[f64],
    h: &[f64],
    rinv: &[f64],
    x: &mut [f64],
    rows: usize,
) {
    let chunks = rows / 4;
    let mut c0 = 0;
    while c0 < chunks {
        c0 += match chunks - c0 {
            1 => padded_block::<Q, 1>(y, h, rinv, x, rows, c0),
            2 => padded_block::<Q, 2>(y, h, rinv, x, rows, c0),
            3 => padded_block::<Q, 3>(y, h, rinv, x, rows, c0),
            _ => padded_block::<Q, 4>(y, h, rinv, x, rows, c0),
        };
    }
}

/// Rows `4 c0 .. 4 (c0 + B)` of [`lowrank_right_solve_lt_padded`] through all columns; returns
/// `B`.
#[inline(always)]
fn padded_block<const Q: usize, const B: usize>(
    y: &[f64],
    h: &[f64],
    rinv: &[f64],
    x: &mut [f64],
    rows: usize,
    c0: usize,
) -> usize {
    let mut acc = [[[0.0f64; 4]; B]; Q];
    for (i, &inv) in rinv.iter().enumerate() {
        let yi: &[f64; Q] = y[i * Q..(i + 1) * Q].try_into().expect("y");
        let hi: &[f64; Q] = h[i * Q..(i + 1) * Q].try_into().expect("h");
        let xs = &mut x[i * rows + 4 * c0..i * rows + 4 * (c0 + B)];
        for b in 0..B {
            let xv: &mut [f64; 4] = (&mut xs[4 * b..4 * b + 4]).try_into().expect("chunk");
            let mut v = *xv;
            for k in 0..Q {
                for e in 0..4 {
                    v[e] = yi[k].mul_add(acc[k][b][e], v[e]);
                }
            }
            for e in &mut v {
                *e *= inv;
            }
            *xv = v;
            for k in 0..Q {
                for e in 0..4 {
                    acc[k][b][e] = hi[k].mul_add(v[e], acc[k][b][e]);
                }
            }
        }
    }
    B
}
