//! Square operators (the Lawson propagators `e^{hL/2}`): dense, block diagonal, or sparse
//! with rows grouped by column pattern, applied to vectors and to the transposed
//! sensitivity layout.

use super::{axpy, fmut, fref, gemv, gemv_t};
use faer::linalg::matmul::matmul;
use faer::traits::pulp::{Arch, Simd, WithSimd};
use faer::{Accum, Par};
use nalgebra::DMatrix;

/// A square operator that is either dense or stored by rows with its nonzeros only
/// (the exponential of a block-diagonal modal `W` is block diagonal).
#[derive(Clone, Debug)]
pub(crate) enum Operator {
    /// Dense storage.
    Dense(DMatrix<f64>),
    /// The nonzeros by rows, rows grouped by column pattern ([`RowGroup`]); the dense copy
    /// serves transposed products.
    Sparse { groups: Vec<RowGroup>, dense: DMatrix<f64> },
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
        Operator::Sparse { groups, dense: m }
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
            Operator::Dense(m) => super::gemm(dst, m, src, alpha, add),
            Operator::BlockDiagonal { blocks, .. } => {
                let n = dst.nrows();
                for (s, d) in
                    src.as_slice().chunks_exact(n).zip(dst.as_mut_slice().chunks_exact_mut(n))
                {
                    block_apply(blocks, d, s, alpha, add);
                }
            }
            Operator::Sparse { .. } => {
                let n = dst.nrows();
                for (s, d) in
                    src.as_slice().chunks_exact(n).zip(dst.as_mut_slice().chunks_exact_mut(n))
                {
                    self.apply_vec(d, s, alpha, add);
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
            Operator::Sparse { groups, .. } => {
                Arch::new().dispatch(GroupedVec { y, x, groups, alpha, add })
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

/// `y = alpha op x` (+= when `add`) over the [`RowGroup`]s of a sparse operator: per row,
/// `acc + v x_c` over its columns in ascending order (a multiply and an add, no FMA), the
/// rows of a group side by side.
struct GroupedVec<'a> {
    y: &'a mut [f64],
    x: &'a [f64],
    groups: &'a [RowGroup],
    alpha: f64,
    add: bool,
}

#[inline(always)]
fn group_vec<const R: usize>(y: &mut [f64], x: &[f64], g: &RowGroup, alpha: f64, add: bool) {
    let mut acc = [0.0_f64; R];
    for (&c, v) in g.cols.iter().zip(g.vals.chunks_exact(R)) {
        let xc = x[c];
        for q in 0..R {
            acc[q] += v[q] * xc;
        }
    }
    for q in 0..R {
        let yi = &mut y[g.rows[q]];
        if add {
            *yi += alpha * acc[q];
        } else {
            *yi = alpha * acc[q];
        }
    }
}

impl WithSimd for GroupedVec<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, _simd: S) {
        let GroupedVec { y, x, groups, alpha, add } = self;
        for g in groups {
            match g.len {
                1 => group_vec::<1>(y, x, g, alpha, add),
                2 => group_vec::<2>(y, x, g, alpha, add),
                3 => group_vec::<3>(y, x, g, alpha, add),
                _ => group_vec::<GROUP>(y, x, g, alpha, add),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::la::{mul_right_t, SparseRightT, SparseRows};
    use rand::Rng;

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
        let Operator::Sparse { groups, .. } = &op else {
            panic!("expected sparse storage");
        };
        let (mut row_ptr, mut col, mut val) = (vec![0], Vec::new(), Vec::new());
        for i in 0..n {
            for j in 0..n {
                if m[(i, j)] != 0.0 {
                    col.push(j);
                    val.push(m[(i, j)]);
                }
            }
            row_ptr.push(col.len());
        }
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
                    col: &col,
                    val: &val,
                    m: rows,
                    alpha: 0.7,
                    add,
                });
                assert_eq!(grouped, by_row, "rows {rows}, add {add}");
                let x = src.row(0).transpose();
                let mut yv = vec![0.5; n];
                op.apply_vec(&mut yv, x.as_slice(), 0.7, add);
                for (i, r) in row_ptr.windows(2).enumerate() {
                    let acc = col[r[0]..r[1]]
                        .iter()
                        .zip(&val[r[0]..r[1]])
                        .fold(0.0, |acc, (&c, &v)| acc + v * x[c]);
                    let expected = if add { 0.5 + 0.7 * acc } else { 0.7 * acc };
                    assert_eq!(yv[i].to_bits(), expected.to_bits(), "row {i}");
                }
                let base =
                    if add { DMatrix::from_element(rows, n, 0.5) } else { DMatrix::zeros(rows, n) };
                assert!((grouped - base - &src * m.transpose() * 0.7).amax() < 1e-13);
            }
        }
    }
}
