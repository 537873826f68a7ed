//! An orthonormal basis `Z` of the null space of a constraint matrix `C` (`C Z = 0`, `ZᵀZ = I`):
//! the linear algebra behind constrained modes (theory.md §4, eq. 32 `X = Z X_p`).
//!
//! Constraint rows touch few columns (end-node velocities, end values), so `Z` keeps every
//! untouched column as a unit vector and takes the rest from a dense SVD (faer) of `C`
//! restricted to the touched columns: the right singular vectors whose singular value is
//! `≤ tol · σ_max`. The result is exactly orthonormal up to round-off and as well conditioned
//! as a basis can be; the rank decision uses the singular values.

use faer::{Mat, MatRef};

use crate::error::{BeamError, Result};

/// The null-space basis of a constraint matrix and what the SVD found.
#[derive(Clone, Debug)]
pub struct NullSpace {
    /// `Z`: `n × (n − rank)`, orthonormal columns spanning `{X : C X = 0}`. Columns: first the
    /// unit vectors of the untouched columns (ascending), then the SVD part.
    pub basis: Mat<f64>,
    /// Numerical rank of `C` (singular values `> tol · σ_max`).
    pub rank: usize,
    /// Singular values of `C` on its touched columns, descending.
    pub singular_values: Vec<f64>,
    /// Left singular vectors of the rank deficiency (`rows × (rows − rank)`): combinations of
    /// rows that vanish, naming redundant or conflicting constraints.
    pub dependent_rows: Mat<f64>,
    /// Largest `|C Z|` entry on the touched columns (a check; round-off).
    pub residual: f64,
}

/// `Z` for a dense constraint matrix `c` (`rows × n`) with relative rank tolerance `tol`.
///
/// ```
/// use faer::mat;
/// use intrinsic_beam::null_space;
///
/// // one constraint x0 = x1 on three unknowns: a two-dimensional null space
/// let c = mat![[1.0, -1.0, 0.0]];
/// let ns = null_space(c.as_ref(), 1e-12)?;
/// assert_eq!((ns.rank, ns.basis.ncols()), (1, 2));
/// assert!(ns.residual < 1e-15);
/// # Ok::<(), intrinsic_beam::BeamError>(())
/// ```
pub fn null_space(c: MatRef<'_, f64>, tol: f64) -> Result<NullSpace> {
    let (rows, n) = (c.nrows(), c.ncols());
    let touched: Vec<usize> = (0..n).filter(|&j| (0..rows).any(|i| c[(i, j)] != 0.0)).collect();
    let untouched: Vec<usize> = (0..n).filter(|j| touched.binary_search(j).is_err()).collect();
    let mut null_cols: Vec<Vec<f64>> = Vec::new();
    let (mut rank, mut singular_values) = (0, Vec::new());
    let mut dependent_rows = Mat::<f64>::zeros(rows, 0);
    let mut residual = 0.0f64;
    if !touched.is_empty() {
        let sub = Mat::from_fn(rows, touched.len(), |i, j| c[(i, touched[j])]);
        let svd = sub.svd().map_err(|e| BeamError::LinearSolve {
            reason: format!("SVD of the constraint rows: {e:?}"),
        })?;
        let s = svd.S().column_vector();
        let smax = (0..s.nrows()).map(|i| s[i]).fold(0.0f64, f64::max);
        rank = (0..s.nrows()).filter(|&i| s[i] > tol * smax).count();
        singular_values = (0..s.nrows()).map(|i| s[i]).collect();
        let v = svd.V();
        for col in rank..touched.len() {
            null_cols.push((0..touched.len()).map(|i| v[(i, col)]).collect());
        }
        let u = svd.U();
        dependent_rows = Mat::from_fn(rows, rows - rank.min(rows), |i, j| u[(i, rank + j)]);
        let zs = Mat::from_fn(touched.len(), null_cols.len(), |i, j| null_cols[j][i]);
        let cz = &sub * &zs;
        for j in 0..cz.ncols() {
            for i in 0..cz.nrows() {
                residual = residual.max(cz[(i, j)].abs());
            }
        }
    }
    let mut z = Mat::<f64>::zeros(n, untouched.len() + null_cols.len());
    for (col, &j) in untouched.iter().enumerate() {
        z[(j, col)] = 1.0;
    }
    for (extra, vals) in null_cols.iter().enumerate() {
        for (i, &t) in touched.iter().enumerate() {
            z[(t, untouched.len() + extra)] = vals[i];
        }
    }
    Ok(NullSpace { basis: z, rank, singular_values, dependent_rows, residual })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `C Z = 0`, `ZᵀZ = I`, the untouched columns as unit vectors and the rank of a matrix
    /// with one dependent row.
    #[test]
    fn basis_is_orthonormal_and_annihilated() {
        // rows 0 and 2 are dependent (row 2 = 2 · row 0); column 3 is untouched
        let c = Mat::from_fn(3, 5, |i, j| match (i, j) {
            (_, 3) => 0.0,
            (0, _) => (j as f64 + 1.0).sin(),
            (1, _) => (2.0 * j as f64 + 0.5).cos(),
            (_, _) => 2.0 * (j as f64 + 1.0).sin(),
        });
        let ns = null_space(c.as_ref(), 1e-10).unwrap();
        assert_eq!(ns.rank, 2);
        assert_eq!(ns.basis.ncols(), 3);
        assert_eq!(ns.dependent_rows.ncols(), 1);
        assert_eq!(ns.basis[(3, 0)], 1.0);
        let cz = &c * &ns.basis;
        let ztz = ns.basis.transpose() * &ns.basis;
        for j in 0..ns.basis.ncols() {
            for i in 0..3 {
                assert!(cz[(i, j)].abs() < 1e-14);
            }
            for i in 0..ns.basis.ncols() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((ztz[(i, j)] - want).abs() < 1e-14);
            }
        }
        assert!(ns.residual < 1e-14);
        // the dependent combination is ∝ (2, 0, −1)/√5
        let d = ns.dependent_rows.col(0);
        assert!((d[0].abs() - 2.0 / 5f64.sqrt()).abs() < 1e-12 && d[1].abs() < 1e-12);
    }
}
