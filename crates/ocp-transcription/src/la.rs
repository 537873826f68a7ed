//! Thin helpers: faer kernels (matrix products, Cholesky, LU) on nalgebra column-major storage.

use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::DMatrix;

/// A faer view of a nalgebra matrix.
pub(crate) fn fref(m: &DMatrix<f64>) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(m.as_slice(), m.nrows(), m.ncols())
}

/// A mutable faer view of a nalgebra matrix.
pub(crate) fn fmut(m: &mut DMatrix<f64>) -> MatMut<'_, f64> {
    let (r, c) = m.shape();
    MatMut::from_column_major_slice_mut(m.as_mut_slice(), r, c)
}

/// `dst = alpha * a * b` (or `dst += alpha * a * b` when `add`).
pub(crate) fn gemm(
    dst: &mut DMatrix<f64>,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    alpha: f64,
    add: bool,
) {
    let acc = if add { Accum::Add } else { Accum::Replace };
    matmul(fmut(dst), acc, fref(a), fref(b), alpha, Par::Seq);
}

/// `dst = alpha * aᵀ * b` (or `+=` when `add`).
pub(crate) fn gemm_tn(
    dst: &mut DMatrix<f64>,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    alpha: f64,
    add: bool,
) {
    let acc = if add { Accum::Add } else { Accum::Replace };
    matmul(fmut(dst), acc, fref(a).transpose(), fref(b), alpha, Par::Seq);
}

/// `y = alpha * a * x` (+= when `add`) for slices.
pub(crate) fn gemv(y: &mut [f64], a: &DMatrix<f64>, x: &[f64], alpha: f64, add: bool) {
    let acc = if add { Accum::Add } else { Accum::Replace };
    let n = y.len();
    let m = x.len();
    matmul(
        MatMut::from_column_major_slice_mut(y, n, 1),
        acc,
        fref(a),
        MatRef::from_column_major_slice(x, m, 1),
        alpha,
        Par::Seq,
    );
}

/// `y = alpha * aᵀ * x` (+= when `add`) for slices.
pub(crate) fn gemv_t(y: &mut [f64], a: &DMatrix<f64>, x: &[f64], alpha: f64, add: bool) {
    let acc = if add { Accum::Add } else { Accum::Replace };
    let n = y.len();
    let m = x.len();
    matmul(
        MatMut::from_column_major_slice_mut(y, n, 1),
        acc,
        fref(a).transpose(),
        MatRef::from_column_major_slice(x, m, 1),
        alpha,
        Par::Seq,
    );
}

/// Max norm of a slice (NaN propagates as NaN).
pub(crate) fn norm_inf(x: &[f64]) -> f64 {
    let mut m = 0.0_f64;
    for &v in x {
        if v.is_nan() {
            return f64::NAN;
        }
        m = m.max(v.abs());
    }
    m
}

/// Whether all entries are finite.
pub(crate) fn all_finite(x: &[f64]) -> bool {
    x.iter().all(|v| v.is_finite())
}

/// `y += a * x`.
pub(crate) fn axpy(y: &mut [f64], a: f64, x: &[f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

/// A square operator that is either dense or stored by rows with its nonzeros only
/// (the exponential of a block-diagonal modal `W` is block diagonal).
#[derive(Clone, Debug)]
pub(crate) enum Operator {
    /// Dense storage.
    Dense(DMatrix<f64>),
    /// Compressed rows: `(row_ptr, col, val)`; the dense copy serves transposed products.
    Sparse { row_ptr: Vec<usize>, col: Vec<usize>, val: Vec<f64>, dense: DMatrix<f64> },
}

impl Operator {
    /// Stores `m` sparse when at most 30 % of its entries are nonzero.
    pub(crate) fn new(m: DMatrix<f64>) -> Self {
        let n = m.nrows();
        let nnz = m.iter().filter(|v| **v != 0.0).count();
        if nnz * 10 > 3 * n * n {
            return Operator::Dense(m);
        }
        let mut row_ptr = Vec::with_capacity(n + 1);
        let mut col = Vec::with_capacity(nnz);
        let mut val = Vec::with_capacity(nnz);
        row_ptr.push(0);
        for i in 0..n {
            for j in 0..m.ncols() {
                let v = m[(i, j)];
                if v != 0.0 {
                    col.push(j);
                    val.push(v);
                }
            }
            row_ptr.push(col.len());
        }
        Operator::Sparse { row_ptr, col, val, dense: m }
    }

    /// The dense matrix.
    pub(crate) fn dense(&self) -> &DMatrix<f64> {
        match self {
            Operator::Dense(m) => m,
            Operator::Sparse { dense, .. } => dense,
        }
    }

    /// `dst = alpha * op * src` (+= when `add`), `src` and `dst` with the same shape.
    pub(crate) fn apply(&self, dst: &mut DMatrix<f64>, src: &DMatrix<f64>, alpha: f64, add: bool) {
        match self {
            Operator::Dense(m) => gemm(dst, m, src, alpha, add),
            Operator::Sparse { row_ptr, col, val, .. } => {
                let n = dst.nrows();
                for j in 0..src.ncols() {
                    let s = src.column(j);
                    let mut d = dst.column_mut(j);
                    for i in 0..n {
                        let mut acc = 0.0;
                        for p in row_ptr[i]..row_ptr[i + 1] {
                            acc += val[p] * s[col[p]];
                        }
                        if add {
                            d[i] += alpha * acc;
                        } else {
                            d[i] = alpha * acc;
                        }
                    }
                }
            }
        }
    }

    /// `y = alpha * op * x` (+= when `add`).
    pub(crate) fn apply_vec(&self, y: &mut [f64], x: &[f64], alpha: f64, add: bool) {
        match self {
            Operator::Dense(m) => gemv(y, m, x, alpha, add),
            Operator::Sparse { row_ptr, col, val, .. } => {
                for i in 0..y.len() {
                    let mut acc = 0.0;
                    for p in row_ptr[i]..row_ptr[i + 1] {
                        acc += val[p] * x[col[p]];
                    }
                    if add {
                        y[i] += alpha * acc;
                    } else {
                        y[i] = alpha * acc;
                    }
                }
            }
        }
    }

    /// `y = alpha * opᵀ * x` (+= when `add`).
    pub(crate) fn apply_t_vec(&self, y: &mut [f64], x: &[f64], alpha: f64, add: bool) {
        gemv_t(y, self.dense(), x, alpha, add)
    }
}
