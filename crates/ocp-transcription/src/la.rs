//! Thin helpers: faer kernels (matrix products, Cholesky, LU) on nalgebra column-major storage.

use faer::linalg::matmul::matmul;
use faer::reborrow::ReborrowMut;
use faer::traits::pulp::{Arch, Simd, WithSimd};
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

/// Rows of a sparse operator that share one column pattern, at most [`GROUP`] of them:
/// on the transposed layout their output columns are accumulated together, so each loaded
/// chunk of an input column serves every row of the group (a modal `e^{hW/2}` is a few
/// dense diagonal blocks up to a permutation: its rows come in groups of equal patterns).
#[derive(Clone, Debug)]
pub(crate) struct RowGroup {
    rows: [usize; GROUP],
    /// Number of rows in the group (1 to [`GROUP`]).
    len: usize,
    cols: Vec<usize>,
    /// `vals[k · len + q]` = entry of row `rows[q]` in column `cols[k]`.
    vals: Vec<f64>,
}

/// Rows per [`RowGroup`]: 4 rows × 8 directions are 8 AVX2 accumulators.
const GROUP: usize = 4;

impl RowGroup {
    /// Groups the compressed rows `(row_ptr, col, val)` by equal column patterns (in order of
    /// first appearance, split into groups of at most [`GROUP`] rows).
    fn of(row_ptr: &[usize], col: &[usize], val: &[f64]) -> Vec<RowGroup> {
        let n = row_ptr.len() - 1;
        let pattern = |i: usize| &col[row_ptr[i]..row_ptr[i + 1]];
        let mut taken = vec![false; n];
        let mut groups = Vec::new();
        for i in 0..n {
            if taken[i] {
                continue;
            }
            let same: Vec<usize> =
                (i..n).filter(|&r| !taken[r] && pattern(r) == pattern(i)).collect();
            for chunk in same.chunks(GROUP) {
                let mut rows = [0; GROUP];
                rows[..chunk.len()].copy_from_slice(chunk);
                let cols = pattern(i).to_vec();
                let mut vals = Vec::with_capacity(cols.len() * chunk.len());
                for k in 0..cols.len() {
                    for &r in chunk {
                        vals.push(val[row_ptr[r] + k]);
                        taken[r] = true;
                    }
                }
                groups.push(RowGroup { rows, len: chunk.len(), cols, vals });
            }
        }
        groups
    }
}

/// `dst = alpha src · opᵀ` (+= when `add`) over the [`RowGroup`]s of a sparse operator: the
/// same sums in the same order as [`SparseRightT`] (per entry, the FMA chain over the row's
/// columns in ascending order), with `len` output columns accumulated at once.
struct GroupedRightT<'a> {
    dst: &'a mut [f64],
    src: &'a [f64],
    groups: &'a [RowGroup],
    m: usize,
    alpha: f64,
    add: bool,
}

/// `W` directions from `c0` of the `R` output columns of group `g`.
#[inline(always)]
fn group_chunk<const R: usize, const W: usize>(
    dst: &mut [f64],
    src: &[f64],
    g: &RowGroup,
    m: usize,
    c0: usize,
    alpha: f64,
    add: bool,
) {
    let mut acc = [[0.0_f64; W]; R];
    for (&c, v) in g.cols.iter().zip(g.vals.chunks_exact(R)) {
        let s: &[f64; W] = src[c * m + c0..c * m + c0 + W].try_into().expect("chunk width");
        for q in 0..R {
            for t in 0..W {
                acc[q][t] = v[q].mul_add(s[t], acc[q][t]);
            }
        }
    }
    for q in 0..R {
        let r = g.rows[q];
        let dd: &mut [f64; W] =
            (&mut dst[r * m + c0..r * m + c0 + W]).try_into().expect("chunk width");
        if add {
            for t in 0..W {
                dd[t] = alpha.mul_add(acc[q][t], dd[t]);
            }
        } else {
            for t in 0..W {
                dd[t] = alpha * acc[q][t];
            }
        }
    }
}

/// All directions of the `R` output columns of group `g` (chunks of 8, then 4, 2, 1).
#[inline(always)]
fn group_rows<const R: usize>(
    dst: &mut [f64],
    src: &[f64],
    g: &RowGroup,
    m: usize,
    alpha: f64,
    add: bool,
) {
    let mut c0 = 0;
    while c0 + 8 <= m {
        group_chunk::<R, 8>(dst, src, g, m, c0, alpha, add);
        c0 += 8;
    }
    if c0 + 4 <= m {
        group_chunk::<R, 4>(dst, src, g, m, c0, alpha, add);
        c0 += 4;
    }
    if c0 + 2 <= m {
        group_chunk::<R, 2>(dst, src, g, m, c0, alpha, add);
        c0 += 2;
    }
    if c0 < m {
        group_chunk::<R, 1>(dst, src, g, m, c0, alpha, add);
    }
}

impl WithSimd for GroupedRightT<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let GroupedRightT { dst, src, groups, m, alpha, add } = self;
        for g in groups {
            match g.len {
                1 => group_rows::<1>(dst, src, g, m, alpha, add),
                2 => group_rows::<2>(dst, src, g, m, alpha, add),
                3 => group_rows::<3>(dst, src, g, m, alpha, add),
                _ => group_rows::<GROUP>(dst, src, g, m, alpha, add),
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

/// A square operator that is either dense or stored by rows with its nonzeros only
/// (the exponential of a block-diagonal modal `W` is block diagonal).
#[derive(Clone, Debug)]
pub(crate) enum Operator {
    /// Dense storage.
    Dense(DMatrix<f64>),
    /// Compressed rows: `(row_ptr, col, val)`, the same rows grouped by column pattern
    /// (products on the transposed layout); the dense copy serves transposed products.
    Sparse {
        row_ptr: Vec<usize>,
        col: Vec<usize>,
        val: Vec<f64>,
        groups: Vec<RowGroup>,
        dense: DMatrix<f64>,
    },
    /// Block diagonal with small diagonal blocks `(start, size, column-major values)`.
    BlockDiagonal { blocks: Vec<(usize, usize, Vec<f64>)>, dense: DMatrix<f64> },
}

/// Contiguous diagonal blocks of a square matrix's sparsity pattern (largest block size).
fn diagonal_blocks(m: &DMatrix<f64>) -> (Vec<(usize, usize)>, usize) {
    let n = m.nrows();
    let mut blocks = Vec::new();
    let mut largest = 0;
    let mut start = 0;
    while start < n {
        let mut end = start + 1;
        loop {
            let mut new_end = end;
            for r in start..n {
                for c in start..n {
                    let inside_r = r < end;
                    let inside_c = c < end;
                    if (inside_r || inside_c) && m[(r, c)] != 0.0 {
                        new_end = new_end.max(r + 1).max(c + 1);
                    }
                }
            }
            if new_end == end {
                break;
            }
            end = new_end;
        }
        blocks.push((start, end - start));
        largest = largest.max(end - start);
        start = end;
    }
    (blocks, largest)
}

impl Operator {
    /// Stores `m` block diagonal when its blocks are at most 8 × 8, sparse when at most 30 %
    /// of its entries are nonzero, dense otherwise.
    pub(crate) fn new(m: DMatrix<f64>) -> Self {
        let n = m.nrows();
        let (blocks, largest) = diagonal_blocks(&m);
        if largest <= 8 && n > 8 {
            let blocks = blocks
                .into_iter()
                .map(|(s, b)| (s, b, m.view((s, s), (b, b)).iter().copied().collect()))
                .collect();
            return Operator::BlockDiagonal { blocks, dense: m };
        }
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
        let groups = RowGroup::of(&row_ptr, &col, &val);
        Operator::Sparse { row_ptr, col, val, groups, dense: m }
    }

    /// The dense matrix.
    pub(crate) fn dense(&self) -> &DMatrix<f64> {
        match self {
            Operator::Dense(m) => m,
            Operator::Sparse { dense, .. } | Operator::BlockDiagonal { dense, .. } => dense,
        }
    }

    /// `dst = alpha * op * src` (+= when `add`), `src` and `dst` with the same shape.
    #[cfg(test)]
    pub(crate) fn apply(&self, dst: &mut DMatrix<f64>, src: &DMatrix<f64>, alpha: f64, add: bool) {
        match self {
            Operator::Dense(m) => gemm(dst, m, src, alpha, add),
            Operator::BlockDiagonal { blocks, .. } => {
                let n = dst.nrows();
                for (s, d) in
                    src.as_slice().chunks_exact(n).zip(dst.as_mut_slice().chunks_exact_mut(n))
                {
                    block_apply(blocks, d, s, alpha, add);
                }
            }
            Operator::Sparse { row_ptr, col, val, .. } => {
                let n = dst.nrows();
                let src = src.as_slice();
                let dst = dst.as_mut_slice();
                for (s, d) in src.chunks_exact(n).zip(dst.chunks_exact_mut(n)) {
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

    /// `dst = alpha * src * opᵀ` (+= when `add`): the operator applied to the transposed
    /// layout (column `i` of `dst` is `alpha Σ_k op[i, k] src[:, k]`).
    pub(crate) fn apply_right_t(
        &self,
        dst: &mut DMatrix<f64>,
        src: &DMatrix<f64>,
        alpha: f64,
        add: bool,
    ) {
        let m = src.nrows();
        match self {
            Operator::Dense(e) => {
                let acc = if add { Accum::Add } else { Accum::Replace };
                matmul(fmut(dst), acc, fref(src), fref(e).transpose(), alpha, Par::Seq);
            }
            Operator::BlockDiagonal { blocks, .. } => {
                let ss = src.as_slice();
                let ds = dst.as_mut_slice();
                for (start, b, v) in blocks {
                    let (start, b) = (*start, *b);
                    for r in 0..b {
                        let d = &mut ds[(start + r) * m..(start + r + 1) * m];
                        if !add {
                            d.fill(0.0);
                        }
                        for c in 0..b {
                            let w = alpha * v[r + c * b];
                            if w != 0.0 {
                                axpy(d, w, &ss[(start + c) * m..(start + c + 1) * m]);
                            }
                        }
                    }
                }
            }
            Operator::Sparse { groups, .. } => Arch::new().dispatch(GroupedRightT {
                dst: dst.as_mut_slice(),
                src: src.as_slice(),
                groups,
                m,
                alpha,
                add,
            }),
        }
    }

    /// `y = alpha * op * x` (+= when `add`).
    pub(crate) fn apply_vec(&self, y: &mut [f64], x: &[f64], alpha: f64, add: bool) {
        match self {
            Operator::Dense(m) => gemv(y, m, x, alpha, add),
            Operator::BlockDiagonal { blocks, .. } => block_apply(blocks, y, x, alpha, add),
            Operator::Sparse { row_ptr, col, val, .. } => {
                for (yi, r) in y.iter_mut().zip(row_ptr.windows(2)) {
                    let acc = col[r[0]..r[1]]
                        .iter()
                        .zip(&val[r[0]..r[1]])
                        .fold(0.0, |acc, (&c, &v)| acc + v * x[c]);
                    if add {
                        *yi += alpha * acc;
                    } else {
                        *yi = alpha * acc;
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

/// `d = alpha * blockdiag * s` (+= when add) for one column.
fn block_apply(
    blocks: &[(usize, usize, Vec<f64>)],
    d: &mut [f64],
    s: &[f64],
    alpha: f64,
    add: bool,
) {
    for (start, b, v) in blocks {
        let (start, b) = (*start, *b);
        match b {
            1 => {
                let y = alpha * v[0] * s[start];
                if add {
                    d[start] += y;
                } else {
                    d[start] = y;
                }
            }
            2 => {
                let (x0, x1) = (s[start], s[start + 1]);
                let y0 = alpha * (v[0] * x0 + v[2] * x1);
                let y1 = alpha * (v[1] * x0 + v[3] * x1);
                if add {
                    d[start] += y0;
                    d[start + 1] += y1;
                } else {
                    d[start] = y0;
                    d[start + 1] = y1;
                }
            }
            _ => {
                for r in 0..b {
                    let mut acc = 0.0;
                    for c in 0..b {
                        acc += v[r + c * b] * s[start + c];
                    }
                    if add {
                        d[start + r] += alpha * acc;
                    } else {
                        d[start + r] = alpha * acc;
                    }
                }
            }
        }
    }
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

    /// The three storages give the same products as the dense matrix.
    #[test]
    fn operator_storages_agree() {
        let n = 11;
        let mut rng = crate::samples::seeded(1);
        let mut bd = DMatrix::zeros(n, n);
        for p in 0..n / 2 {
            for r in 0..2 {
                for c in 0..2 {
                    bd[(2 * p + r, 2 * p + c)] = rng.random_range(-1.0..1.0);
                }
            }
        }
        bd[(n - 1, n - 1)] = 0.7;
        let mut sp = bd.clone();
        sp[(0, n - 1)] = 0.3; // couples first and last: one big block, still sparse
        let dense = DMatrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
        let src = DMatrix::from_fn(n, 3, |_, _| rng.random_range(-1.0..1.0));
        for (m, kind) in [(bd, 0), (sp, 1), (dense, 2)] {
            let op = Operator::new(m.clone());
            match (kind, &op) {
                (0, Operator::BlockDiagonal { .. })
                | (1, Operator::Sparse { .. })
                | (2, Operator::Dense(_)) => {}
                _ => panic!("unexpected storage for kind {kind}"),
            }
            let mut dst = DMatrix::from_element(n, 3, 1.0);
            op.apply(&mut dst, &src, 2.0, true);
            let expected = DMatrix::from_element(n, 3, 1.0) + &m * &src * 2.0;
            assert!((dst - expected).amax() < 1e-14);
            let srct = src.transpose();
            let mut dt = DMatrix::from_element(3, n, 1.0);
            op.apply_right_t(&mut dt, &srct, 2.0, true);
            let expected_t = DMatrix::from_element(3, n, 1.0) + &srct * m.transpose() * 2.0;
            assert!((dt - expected_t).amax() < 1e-14);
            let mut prod = DMatrix::zeros(3, n);
            mul_right_t(&mut prod, &srct, &m, &mut SparseRows::with_capacity(n));
            assert!((prod - &srct * m.transpose()).amax() < 1e-14);
            let mut y = vec![0.0; n];
            op.apply_vec(&mut y, src.column(0).as_slice(), 1.0, false);
            let e = &m * src.column(0);
            assert!(y.iter().zip(e.iter()).all(|(a, b)| (a - b).abs() < 1e-14));
        }
    }

    /// A sparse operator that is dense diagonal blocks up to a permutation: its rows are
    /// grouped by pattern, and the grouped product gives the row-by-row kernel's bits.
    #[test]
    fn grouped_rows_match_row_kernel_bitwise() {
        let n = 37;
        let mut rng = crate::samples::seeded(3);
        let mut perm: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            perm.swap(i, rng.random_range(0..=i));
        }
        let mut m = DMatrix::zeros(n, n);
        let mut start = 0;
        for b in [1, 6, 2, 9, 3, 1, 5, 7, 3].into_iter().cycle() {
            let b = b.min(n - start);
            for r in start..start + b {
                for c in start..start + b {
                    m[(perm[r], perm[c])] = rng.random_range(-1.0..1.0);
                }
            }
            start += b;
            if start == n {
                break;
            }
        }
        let op = Operator::new(m.clone());
        let Operator::Sparse { row_ptr, col, val, groups, .. } = &op else {
            panic!("expected sparse storage");
        };
        assert!(groups.iter().any(|g| g.len == GROUP), "groups {}", groups.len());
        assert_eq!(groups.iter().map(|g| g.len).sum::<usize>(), n);
        for rows in [58, 7, 1] {
            let src = DMatrix::from_fn(rows, n, |_, _| rng.random_range(-1.0..1.0));
            for add in [false, true] {
                let mut grouped = DMatrix::from_element(rows, n, 0.5);
                op.apply_right_t(&mut grouped, &src, 0.7, add);
                let mut by_row = DMatrix::from_element(rows, n, 0.5);
                Arch::new().dispatch(SparseRightT {
                    dst: by_row.as_mut_slice(),
                    src: src.as_slice(),
                    row_ptr: &row_ptr[..n],
                    row_end: &row_ptr[1..],
                    col,
                    val,
                    m: rows,
                    alpha: 0.7,
                    add,
                });
                assert_eq!(grouped, by_row, "rows {rows}, add {add}");
                let base =
                    if add { DMatrix::from_element(rows, n, 0.5) } else { DMatrix::zeros(rows, n) };
                assert!((grouped - base - &src * m.transpose() * 0.7).amax() < 1e-13);
            }
        }
    }
}
