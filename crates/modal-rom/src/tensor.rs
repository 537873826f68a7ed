//! Sparse third-order tensors `T^l_ij` stored as their nonzero entries (the modal `Γ`s).

use serde::{Deserialize, Serialize};

/// A third-order tensor `T^l_ij` (`i < ni`, `j < nj`, `l < nl`) holding only its nonzeros.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SparseTensor3 {
    /// Dimensions `(ni, nj, nl)`.
    pub dims: (usize, usize, usize),
    /// Nonzero entries `(i, j, l, value)`, sorted by `(l, i, j)`.
    pub entries: Vec<(u32, u32, u32, f64)>,
}

impl SparseTensor3 {
    /// Builds from a dense evaluator `f(i, j, l)`, keeping entries with `|v| > drop`.
    pub fn from_fn(
        dims: (usize, usize, usize),
        drop: f64,
        mut f: impl FnMut(usize, usize, usize) -> f64,
    ) -> Self {
        let mut entries = Vec::new();
        for l in 0..dims.2 {
            for i in 0..dims.0 {
                for j in 0..dims.1 {
                    let v = f(i, j, l);
                    if v.abs() > drop {
                        entries.push((i as u32, j as u32, l as u32, v));
                    }
                }
            }
        }
        SparseTensor3 { dims, entries }
    }

    /// Builds from a dense array indexed `[(l * ni + i) * nj + j]`, keeping `|v| > drop`.
    pub fn from_dense(dims: (usize, usize, usize), dense: &[f64], drop: f64) -> Self {
        Self::from_fn(dims, drop, |i, j, l| dense[(l * dims.0 + i) * dims.1 + j])
    }

    /// Number of stored nonzeros.
    pub fn nnz(&self) -> usize {
        self.entries.len()
    }

    /// Fill ratio `nnz / (ni nj nl)` (0 for an empty shape).
    pub fn fill(&self) -> f64 {
        let total = self.dims.0 * self.dims.1 * self.dims.2;
        if total == 0 {
            0.0
        } else {
            self.nnz() as f64 / total as f64
        }
    }

    /// Dense copy indexed `[(l * ni + i) * nj + j]` (the export layout, `T[l, i, j]`).
    pub fn to_dense(&self) -> Vec<f64> {
        let (ni, nj, nl) = self.dims;
        let mut out = vec![0.0; ni * nj * nl];
        for &(i, j, l, v) in &self.entries {
            out[(l as usize * ni + i as usize) * nj + j as usize] = v;
        }
        out
    }

    /// Largest |entry|.
    pub fn max_abs(&self) -> f64 {
        self.entries.iter().fold(0.0f64, |a, e| a.max(e.3.abs()))
    }
}
