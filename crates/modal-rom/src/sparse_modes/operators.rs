//! Sparse building blocks of the sparse eigen route: compressed rows, and the element-block
//! factors `B2 = L2 L2ᵀ` and `B1^{+½}` (`docs/theory.md §4`).

use crate::blocks::BlockDiag;
use crate::error::{ModalError, Result};
pub(crate) use crate::sparse_problem::Csr;

/// Dense lower Cholesky factor of the `r × r` row-major `a`, or `None` if not positive definite.
fn cholesky(a: &[f64], r: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; r * r];
    for j in 0..r {
        let mut d = a[j * r + j];
        for p in 0..j {
            d -= l[j * r + p] * l[j * r + p];
        }
        if d.is_nan() || d <= 0.0 {
            return None;
        }
        let d = d.sqrt();
        l[j * r + j] = d;
        for i in j + 1..r {
            let mut s = a[i * r + j];
            for p in 0..j {
                s -= l[i * r + p] * l[j * r + p];
            }
            l[i * r + j] = s / d;
        }
    }
    Some(l)
}

/// `B2 = L2 L2ᵀ` by element blocks, on the non-rigid entries of each block (rows that are not
/// all zero; the rigid ones are `C = 0`, theory.md §1).
#[derive(Clone, Debug)]
pub(crate) struct FactoredBlocks {
    k: usize,
    active: Vec<Vec<usize>>,
    l: Vec<Vec<f64>>,
}

impl FactoredBlocks {
    pub(crate) fn compliance(what: &str, b: &BlockDiag) -> Result<Self> {
        let k = b.k();
        let (mut active, mut l) = (Vec::new(), Vec::new());
        for e in 0..b.n_blocks() {
            let blk = b.block(e);
            let a: Vec<usize> = (0..k).filter(|&i| (0..k).any(|j| blk[i * k + j] != 0.0)).collect();
            let r = a.len();
            let sub: Vec<f64> = (0..r * r).map(|p| blk[a[p / r] * k + a[p % r]]).collect();
            let f = cholesky(&sub, r).ok_or_else(|| ModalError::Numerical {
                stage: format!("Cholesky of an element compliance block {what}"),
                reason: format!(
                    "block {e} is not positive definite (a compliance matrix C must be \
                     positive definite on its non-rigid entries)"
                ),
            })?;
            active.push(a);
            l.push(f);
        }
        Ok(FactoredBlocks { k, active, l })
    }

    /// `y ← L2⁻¹ y` (zero on rigid entries).
    pub(crate) fn lower_solve(&self, y: &mut [f64]) {
        for (e, (a, l)) in self.active.iter().zip(&self.l).enumerate() {
            let (r, o) = (a.len(), e * self.k);
            let mut z: Vec<f64> = a.iter().map(|&i| y[o + i]).collect();
            for i in 0..r {
                let s: f64 = (0..i).map(|p| l[i * r + p] * z[p]).sum();
                z[i] = (z[i] - s) / l[i * r + i];
            }
            (0..self.k).for_each(|i| y[o + i] = 0.0);
            a.iter().zip(&z).for_each(|(&i, &v)| y[o + i] = v);
        }
    }

    /// `y ← L2⁻ᵀ y` (zero on rigid entries).
    pub(crate) fn upper_solve(&self, y: &mut [f64]) {
        for (e, (a, l)) in self.active.iter().zip(&self.l).enumerate() {
            let (r, o) = (a.len(), e * self.k);
            let mut z: Vec<f64> = a.iter().map(|&i| y[o + i]).collect();
            for i in (0..r).rev() {
                let s: f64 = (i + 1..r).map(|p| l[p * r + i] * z[p]).sum();
                z[i] = (z[i] - s) / l[i * r + i];
            }
            (0..self.k).for_each(|i| y[o + i] = 0.0);
            a.iter().zip(&z).for_each(|(&i, &v)| y[o + i] = v);
        }
    }
}

/// `B1^{+½}` by node blocks: `U Λ^{−½} Uᵀ` over the eigenvalues above `tol` of each block's
/// largest (its massive directions).
#[derive(Clone, Debug)]
pub(crate) struct MassRoot {
    k: usize,
    p: Vec<Vec<f64>>,
}

impl MassRoot {
    pub(crate) fn new(b: &BlockDiag, tol: f64) -> Self {
        let k = b.k();
        let p = (0..b.n_blocks())
            .map(|n| {
                let m = nalgebra::DMatrix::from_row_slice(k, k, b.block(n));
                let eig = m.symmetric_eigen();
                let lmax = eig.eigenvalues.iter().fold(0.0f64, |a, v| a.max(*v));
                let mut out = vec![0.0; k * k];
                for (c, &lam) in eig.eigenvalues.iter().enumerate() {
                    if lam > tol * lmax && lam > 0.0 {
                        let s = 1.0 / lam.sqrt();
                        for i in 0..k {
                            for j in 0..k {
                                out[i * k + j] +=
                                    s * eig.eigenvectors[(i, c)] * eig.eigenvectors[(j, c)];
                            }
                        }
                    }
                }
                out
            })
            .collect();
        MassRoot { k, p }
    }

    /// `x ← B1^{+½} x`.
    pub(crate) fn apply(&self, x: &mut [f64]) {
        let k = self.k;
        for (n, p) in self.p.iter().enumerate() {
            let z: Vec<f64> =
                (0..k).map(|i| (0..k).map(|j| p[i * k + j] * x[n * k + j]).sum()).collect();
            x[n * k..n * k + k].copy_from_slice(&z);
        }
    }
}
