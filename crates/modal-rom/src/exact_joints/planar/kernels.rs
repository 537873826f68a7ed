//! Register kernels of the planar evaluation (module docs of [`super`]): small products and
//! the low-rank frame factor and right solve of [`crate::exact_joints::frame`] in forms whose
//! running sums stay in registers or whose columns do not wait on each other (theory.md §10.4,
//! §10.9).

use crate::exact_joints::frame::{gemv, small_size};
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
