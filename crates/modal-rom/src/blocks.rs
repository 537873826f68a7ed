//! Block-diagonal operators (`B1 = blkdiag(w_n M)`, `B2 = blkdiag(h_e C)`) applied block by block.

use crate::error::{invalid, Result};
use faer::{Mat, MatRef};

/// A block-diagonal matrix with square `k × k` blocks.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockDiag {
    k: usize,
    blocks: Vec<Vec<f64>>,
}

impl BlockDiag {
    /// Extracts the `k × k` diagonal blocks of `m`, checking that every entry outside them is 0.
    pub fn from_dense(what: &str, m: MatRef<'_, f64>, k: usize) -> Result<Self> {
        let n = m.nrows();
        if n % k != 0 || m.ncols() != n {
            return Err(invalid(
                what,
                format!("{}x{}", m.nrows(), m.ncols()),
                format!("must be square with size a multiple of {k}"),
            ));
        }
        for j in 0..n {
            for i in 0..n {
                if i / k != j / k && m[(i, j)] != 0.0 {
                    return Err(invalid(
                        format!("{what}[({i}, {j})]"),
                        m[(i, j)],
                        format!("must be block diagonal with {k}×{k} blocks"),
                    ));
                }
            }
        }
        let blocks = (0..n / k)
            .map(|b| (0..k * k).map(|rc| m[(b * k + rc / k, b * k + rc % k)]).collect())
            .collect();
        Ok(BlockDiag { k, blocks })
    }

    /// Collects `(row, col, value)` entries of an `n × n` matrix (duplicates summed, in order)
    /// into `k × k` diagonal blocks, checking that none lies outside them.
    pub(crate) fn from_entries(
        what: &str,
        n: usize,
        k: usize,
        entries: &[(usize, usize, f64)],
    ) -> Result<Self> {
        if n % k != 0 {
            return Err(invalid(what, n, format!("size must be a multiple of {k}")));
        }
        let mut blocks = vec![vec![0.0; k * k]; n / k];
        for &(i, j, v) in entries {
            if i >= n || j >= n || i / k != j / k {
                if v == 0.0 && i < n && j < n {
                    continue;
                }
                return Err(invalid(
                    format!("{what}[({i}, {j})]"),
                    v,
                    format!("must be block diagonal with {k}×{k} blocks"),
                ));
            }
            blocks[i / k][(i % k) * k + j % k] += v;
        }
        Ok(BlockDiag { k, blocks })
    }

    /// Block size `k`.
    pub(crate) fn k(&self) -> usize {
        self.k
    }

    /// Number of blocks.
    pub(crate) fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// `self · x` for `x` with `n` rows.
    pub fn apply(&self, x: MatRef<'_, f64>) -> Mat<f64> {
        let k = self.k;
        let mut out = Mat::<f64>::zeros(x.nrows(), x.ncols());
        for j in 0..x.ncols() {
            for (b, blk) in self.blocks.iter().enumerate() {
                for r in 0..k {
                    let mut acc = 0.0;
                    for c in 0..k {
                        acc += blk[r * k + c] * x[(b * k + c, j)];
                    }
                    out[(b * k + r, j)] = acc;
                }
            }
        }
        out
    }

    /// `self · x` for a vector.
    pub fn apply_vec(&self, x: &[f64]) -> Vec<f64> {
        let k = self.k;
        let mut out = vec![0.0; x.len()];
        for (b, blk) in self.blocks.iter().enumerate() {
            for r in 0..k {
                out[b * k + r] = (0..k).map(|c| blk[r * k + c] * x[b * k + c]).sum();
            }
        }
        out
    }

    /// Block `b` (row-major `k × k`).
    pub fn block(&self, b: usize) -> &[f64] {
        &self.blocks[b]
    }
}
