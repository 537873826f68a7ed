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
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, MatMut, MatRef, Par};

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

/// `y (+)= alpha · a x` for column-major `a` (`r × c`).
pub(crate) fn gemv(y: &mut [f64], add: bool, a: &[f64], r: usize, x: &[f64], alpha: f64) {
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

/// `y (+)= alpha · aᵀ x` for column-major `a` (`r × c`, `x` of length `r`).
pub(crate) fn gemv_t(y: &mut [f64], add: bool, a: &[f64], r: usize, x: &[f64], alpha: f64) {
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

/// `M ← M L⁻ᵀ` for `M` (`r × n`, column-major) and lower `L` (`n × n`).
pub(crate) fn right_solve_lt(l: &[f64], n: usize, m: &mut [f64], r: usize) {
    if r == 0 || n == 0 {
        return;
    }
    solve_lower_triangular_in_place(view(l, n, n), view_mut(m, r, n).transpose_mut(), Par::Seq);
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
