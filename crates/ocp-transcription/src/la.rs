//! Thin helpers: faer kernels (matrix products, Cholesky, LU) on nalgebra column-major storage.

use faer::linalg::matmul::matmul;
use faer::reborrow::ReborrowMut;
use faer::traits::pulp::{Arch, Simd, WithSimd};
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::DMatrix;

mod operator;
pub(crate) use operator::Operator;

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

/// Row-compressed scratch for a sparse Jacobian (capacity `n²`, allocated once), and the
/// row groups / column ranges of its nonzero blocks.
#[derive(Clone, Debug, Default)]
pub(crate) struct SparseRows {
    row_ptr: Vec<usize>,
    row_end: Vec<usize>,
    col: Vec<usize>,
    val: Vec<f64>,
    /// Row groups `(r0, r1, first range, end range)` into `ranges`.
    groups: Vec<(usize, usize, usize, usize)>,
    /// Column ranges `[c0, c1)` of the groups.
    ranges: Vec<(usize, usize)>,
    /// Column ranges of the current row (scratch).
    row_ranges: Vec<(usize, usize)>,
    /// Column-major mask of the entries covered by the dense blocks of `groups`/`ranges`
    /// (valid when `blocks_valid`): a later matrix with no nonzero outside it reuses the
    /// blocks without compressing.
    covered: Vec<bool>,
    /// Column-major index runs `[a, b)` outside `covered` (the entries a reuse must find zero).
    uncovered: Vec<(usize, usize)>,
    blocks_valid: bool,
}

/// Zero runs shorter than this are computed through (dense blocks) in [`mul_right_t`].
const RANGE_GAP: usize = 8;

impl SparseRows {
    pub(crate) fn with_capacity(n: usize) -> Self {
        Self {
            row_ptr: vec![0; n + 1],
            row_end: vec![0; n],
            col: vec![0; n * n],
            val: vec![0.0; n * n],
            groups: Vec::with_capacity(n),
            ranges: Vec::with_capacity(n * n),
            row_ranges: Vec::with_capacity(n),
            covered: vec![false; n * n],
            uncovered: Vec::with_capacity(n * n / 2 + 1),
            blocks_valid: false,
        }
    }

    /// Compresses the nonzeros of the column-major `n × n` matrix `j` by rows: row `i`'s
    /// nonzeros go to slots `i·n ..` (`row_ptr[i]` to `row_end[i]`), columns ascending.
    /// One contiguous, branch-free pass over `j` (no allocation); returns the number of
    /// nonzeros.
    fn compress(&mut self, j: &[f64], n: usize) -> usize {
        for i in 0..n {
            self.row_ptr[i] = i * n;
            self.row_end[i] = i * n;
        }
        for (k, column) in j.chunks_exact(n).enumerate() {
            for (i, &v) in column.iter().enumerate() {
                let p = self.row_end[i];
                self.col[p] = k;
                self.val[p] = v;
                self.row_end[i] = p + (v != 0.0) as usize;
            }
        }
        (0..n).map(|i| self.row_end[i] - self.row_ptr[i]).sum()
    }

    /// From the compressed rows: column ranges of each row's nonzeros (zero runs shorter than
    /// [`RANGE_GAP`] merged), consecutive rows with the same number of pairwise overlapping
    /// ranges grouped (ranges united). Returns the entries of the resulting dense blocks.
    fn block_ranges(&mut self, n: usize) -> usize {
        self.groups.clear();
        self.ranges.clear();
        for i in 0..n {
            self.row_ranges.clear();
            for p in self.row_ptr[i]..self.row_end[i] {
                let c = self.col[p];
                match self.row_ranges.last_mut() {
                    Some(last) if c < last.1 + RANGE_GAP => last.1 = c + 1,
                    _ => self.row_ranges.push((c, c + 1)),
                }
            }
            let joins = match self.groups.last() {
                Some(&(_, r1, a, b)) if r1 == i && b - a == self.row_ranges.len() => self.ranges
                    [a..b]
                    .iter()
                    .zip(&self.row_ranges)
                    .all(|(g, r)| r.0 < g.1 + RANGE_GAP && g.0 < r.1 + RANGE_GAP),
                _ => false,
            };
            if joins {
                let g = self.groups.last_mut().expect("joins implies a group");
                g.1 = i + 1;
                for (gr, r) in self.ranges[g.2..g.3].iter_mut().zip(&self.row_ranges) {
                    gr.0 = gr.0.min(r.0);
                    gr.1 = gr.1.max(r.1);
                }
            } else {
                let a = self.ranges.len();
                self.ranges.extend_from_slice(&self.row_ranges);
                self.groups.push((i, i + 1, a, self.ranges.len()));
            }
        }
        self.groups
            .iter()
            .map(|&(r0, r1, a, b)| {
                (r1 - r0) * self.ranges[a..b].iter().map(|r| r.1 - r.0).sum::<usize>()
            })
            .sum()
    }
}

/// `dst = src · jᵀ` for the transposed sensitivity layout (`src`, `dst`: `m × n`, `j`: `n × n`):
/// column `i` of `dst` is `Σ_k j[i, k] · src[:, k]`. The nonzeros of `j` are compressed by
/// rows; when at most 30 % are nonzero each column of `dst` is accumulated in registers over
/// them (one store per column). Otherwise the nonzeros are covered by dense blocks (row groups
/// × column ranges: the zero blocks of a modal ROM's Jacobian, e.g. `(q1, q2) × qξ`, are
/// skipped) and each block is one faer product.
pub(crate) fn mul_right_t(
    dst: &mut DMatrix<f64>,
    src: &DMatrix<f64>,
    j: &DMatrix<f64>,
    rows: &mut SparseRows,
) {
    let n = j.nrows();
    if rows.row_ptr.len() != n + 1 || rows.col.len() < n * n {
        *rows = SparseRows::with_capacity(n);
    }
    let m = src.nrows();
    // the Jacobian's pattern rarely changes between stages: reuse the blocks when every
    // nonzero lies inside them (one branch-free pass, no compression)
    if rows.blocks_valid
        && Arch::new().dispatch(CoveredCheck { j: j.as_slice(), uncovered: &rows.uncovered })
    {
        blocks_product(dst, src, j, rows);
        return;
    }
    rows.blocks_valid = false;
    let nnz = rows.compress(j.as_slice(), n);
    if nnz * 10 <= 3 * n * n {
        Arch::new().dispatch(SparseRightT {
            dst: dst.as_mut_slice(),
            src: src.as_slice(),
            row_ptr: &rows.row_ptr[..n],
            row_end: &rows.row_end,
            col: &rows.col,
            val: &rows.val,
            m,
            alpha: 1.0,
            add: false,
        });
        return;
    }
    let covered = rows.block_ranges(n);
    if covered * 10 > 9 * n * n {
        matmul(fmut(dst), Accum::Replace, fref(src), fref(j).transpose(), 1.0, Par::Seq);
        return;
    }
    rows.covered.fill(false);
    for &(r0, r1, a, b) in &rows.groups {
        for &(c0, c1) in &rows.ranges[a..b] {
            for c in c0..c1 {
                rows.covered[c * n + r0..c * n + r1].fill(true);
            }
        }
    }
    rows.uncovered.clear();
    let mut p = 0;
    while p < n * n {
        if rows.covered[p] {
            p += 1;
            continue;
        }
        let a = p;
        while p < n * n && !rows.covered[p] {
            p += 1;
        }
        rows.uncovered.push((a, p));
    }
    rows.blocks_valid = true;
    blocks_product(dst, src, j, rows);
}

/// `dst = src · jᵀ` over the dense blocks of `rows` (the rest of `j` is zero).
fn blocks_product(dst: &mut DMatrix<f64>, src: &DMatrix<f64>, j: &DMatrix<f64>, rows: &SparseRows) {
    let (jr, sr) = (fref(j), fref(src));
    let mut dm = fmut(dst);
    for &(r0, r1, a, b) in &rows.groups {
        let mut d = dm.rb_mut().subcols_mut(r0, r1 - r0);
        if a == b {
            d.fill(0.0);
        }
        for (q, &(c0, c1)) in rows.ranges[a..b].iter().enumerate() {
            let acc = if q == 0 { Accum::Replace } else { Accum::Add };
            matmul(
                d.rb_mut(),
                acc,
                sr.subcols(c0, c1 - c0),
                jr.submatrix(r0, c0, r1 - r0, c1 - c0).transpose(),
                1.0,
                Par::Seq,
            );
        }
    }
}

/// The sparse kernel of [`mul_right_t`] and of sparse [`Operator`]s: `dst = alpha src · jᵀ`
/// (+= when `add`) with `j` compressed by rows, compiled for the best SIMD level available at
/// run time (pulp dispatch, so the fixed-size accumulators below vectorise with FMA).
struct SparseRightT<'a> {
    dst: &'a mut [f64],
    src: &'a [f64],
    /// Start of each row's nonzeros.
    row_ptr: &'a [usize],
    /// End of each row's nonzeros.
    row_end: &'a [usize],
    col: &'a [usize],
    val: &'a [f64],
    m: usize,
    alpha: f64,
    add: bool,
}

const CHUNK: usize = 16;

/// One chunk of `W` consecutive rows (directions) of column `i` of [`SparseRightT`]:
/// `d[c0..c0 + W] (=|+=) alpha Σ_p val[p] src[col[p]·m + c0 ..][..W]`, accumulated in `W`
/// registers (fixed width, so the loop is fully vectorised and unrolled).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn sparse_chunk<const W: usize>(
    d: &mut [f64],
    src: &[f64],
    cols: &[usize],
    vals: &[f64],
    m: usize,
    c0: usize,
    alpha: f64,
    add: bool,
) {
    let mut acc = [0.0_f64; W];
    for (&c, &v) in cols.iter().zip(vals) {
        let s: &[f64; W] = src[c * m + c0..c * m + c0 + W].try_into().expect("chunk width");
        for t in 0..W {
            acc[t] = v.mul_add(s[t], acc[t]);
        }
    }
    let dd: &mut [f64; W] = (&mut d[c0..c0 + W]).try_into().expect("chunk width");
    if add {
        for t in 0..W {
            dd[t] = alpha.mul_add(acc[t], dd[t]);
        }
    } else {
        // also for alpha = 1 (exact): a plain copy of 16 values compiles to a libc memcpy
        // call (8 % of an interval, measured)
        for t in 0..W {
            dd[t] = alpha * acc[t];
        }
    }
}

impl WithSimd for SparseRightT<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let SparseRightT { dst, src, row_ptr, row_end, col, val, m, alpha, add } = self;
        for i in 0..row_ptr.len() {
            let (cols, vals) = (&col[row_ptr[i]..row_end[i]], &val[row_ptr[i]..row_end[i]]);
            let d = &mut dst[i * m..(i + 1) * m];
            // chunks of 16, then 8, 4, 2, 1 rows: every width is a compile-time constant
            let mut c0 = 0;
            while c0 + CHUNK <= m {
                sparse_chunk::<CHUNK>(d, src, cols, vals, m, c0, alpha, add);
                c0 += CHUNK;
            }
            if c0 + 8 <= m {
                sparse_chunk::<8>(d, src, cols, vals, m, c0, alpha, add);
                c0 += 8;
            }
            if c0 + 4 <= m {
                sparse_chunk::<4>(d, src, cols, vals, m, c0, alpha, add);
                c0 += 4;
            }
            if c0 + 2 <= m {
                sparse_chunk::<2>(d, src, cols, vals, m, c0, alpha, add);
                c0 += 2;
            }
            if c0 < m {
                sparse_chunk::<1>(d, src, cols, vals, m, c0, alpha, add);
            }
        }
    }
}

#[inline(always)]
fn axpy_kernel(y: &mut [f64], a: f64, x: &[f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi = a.mul_add(*xi, *yi);
    }
}

struct Axpy<'a> {
    y: &'a mut [f64],
    a: f64,
    x: &'a [f64],
}

impl WithSimd for Axpy<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        axpy_kernel(self.y, self.a, self.x)
    }
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

struct Lincomb<'a> {
    y: &'a mut [f64],
    x: &'a [f64],
    a: f64,
    z: &'a [f64],
}

impl WithSimd for Lincomb<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        for ((yi, xi), zi) in self.y.iter_mut().zip(self.x).zip(self.z) {
            *yi = self.a.mul_add(*zi, *xi);
        }
    }
}

/// `y = x + a * z` (one pass, SIMD-dispatched).
pub(crate) fn lincomb(y: &mut [f64], x: &[f64], a: f64, z: &[f64]) {
    Arch::new().dispatch(Lincomb { y, x, a, z })
}

struct Lincomb3<'a> {
    y: &'a mut [f64],
    x: &'a [f64],
    a: f64,
    z: &'a [f64],
    b: f64,
    w1: &'a [f64],
    w2: &'a [f64],
}

impl WithSimd for Lincomb3<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let Lincomb3 { y, x, a, z, b, w1, w2 } = self;
        let n = y.len();
        let (x, z, w1, w2) = (&x[..n], &z[..n], &w1[..n], &w2[..n]);
        for i in 0..n {
            y[i] = x[i] + a * z[i] + b * (w1[i] + w2[i]);
        }
    }
}

/// `y = x + a z + b (w1 + w2)`, evaluated as `(x + a·z) + b·(w1 + w2)` with separate
/// multiplies and adds (no FMA: the bits do not depend on the SIMD level); SIMD-dispatched.
pub(crate) fn lincomb3(
    y: &mut [f64],
    x: &[f64],
    a: f64,
    z: &[f64],
    b: f64,
    w1: &[f64],
    w2: &[f64],
) {
    Arch::new().dispatch(Lincomb3 { y, x, a, z, b, w1, w2 })
}

struct CoveredCheck<'a> {
    j: &'a [f64],
    uncovered: &'a [(usize, usize)],
}

impl WithSimd for CoveredCheck<'_> {
    type Output = bool;
    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) -> bool {
        // only the runs outside the blocks are read (a NaN there counts as a nonzero)
        let mut outside = 0usize;
        for &(a, b) in self.uncovered {
            outside += self.j[a..b].iter().map(|v| (*v != 0.0) as usize).sum::<usize>();
        }
        outside == 0
    }
}

/// `y += a * x` (SIMD-dispatched).
pub(crate) fn axpy(y: &mut [f64], a: f64, x: &[f64]) {
    Arch::new().dispatch(Axpy { y, a, x })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    /// An `n × n` Jacobian with the modal ROM's zero blocks: rows below 18 read columns below
    /// 18, the others skip columns 7..18; 80 % of the allowed entries are nonzero.
    fn rom_like_jacobian(n: usize, rng: &mut impl Rng) -> DMatrix<f64> {
        DMatrix::from_fn(n, n, |r, c| {
            let inside = if r < 18 { c < 18 } else { !(7..18).contains(&c) };
            if inside && rng.random_range(0.0..1.0) < 0.8 {
                rng.random_range(-1.0..1.0)
            } else {
                0.0
            }
        })
    }

    /// A Jacobian with the modal ROM's zero blocks (dense-ish, > 30 % nonzero) goes through
    /// the block-range path and gives the dense product, scattered zeros and all.
    #[test]
    fn block_range_product_matches_dense() {
        let n = 30;
        let mut rng = crate::samples::seeded(5);
        let j = rom_like_jacobian(n, &mut rng);
        let src = DMatrix::from_fn(35, n, |_, _| rng.random_range(-1.0..1.0));
        let mut rows = SparseRows::with_capacity(n);
        let mut dst = DMatrix::from_element(35, n, f64::NAN);
        mul_right_t(&mut dst, &src, &j, &mut rows);
        assert!(rows.groups.len() >= 2, "groups {:?}", rows.groups);
        let covered = rows.block_ranges(n);
        assert!(covered * 10 <= 9 * n * n, "covered {covered}");
        assert!((dst - &src * j.transpose()).amax() < 1e-13);
    }

    /// A cached block pattern is reused while the Jacobian's nonzeros stay inside it and
    /// dropped when one appears outside (the product stays the dense one).
    #[test]
    fn block_pattern_reuse_and_change() {
        let n = 30;
        let mut rng = crate::samples::seeded(8);
        let j1 = rom_like_jacobian(n, &mut rng);
        let src = DMatrix::from_fn(35, n, |_, _| rng.random_range(-1.0..1.0));
        let mut rows = SparseRows::with_capacity(n);
        let mut dst = DMatrix::zeros(35, n);
        mul_right_t(&mut dst, &src, &j1, &mut rows);
        assert!(rows.blocks_valid && !rows.uncovered.is_empty());
        let j2 = j1.map(|v| 2.0 * v);
        mul_right_t(&mut dst, &src, &j2, &mut rows);
        assert!(rows.blocks_valid);
        assert!((&dst - &src * j2.transpose()).amax() < 1e-13);
        let mut j3 = j2.clone();
        j3[(3, 25)] = 0.5; // outside the blocks of j1
        mul_right_t(&mut dst, &src, &j3, &mut rows);
        assert!((&dst - &src * j3.transpose()).amax() < 1e-13);
        let mut j4 = j3.clone();
        j4[(3, 25)] = f64::NAN;
        mul_right_t(&mut dst, &src, &j4, &mut rows);
        assert!(dst.column(3).iter().any(|v| v.is_nan()), "NaN must propagate");
    }
}
