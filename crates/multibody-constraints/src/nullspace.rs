//! An orthonormal basis `Z` of the null space of the constraint rows `G` (eq. 32: `X = Z X_p`,
//! `G Z = 0`), for the constrained modes of `modal-rom`.
//!
//! `G` touches only end-node velocities and end values, so most columns are free: `Z` keeps
//! those as unit vectors and takes the rest from a dense SVD (faer) of `G` restricted to the
//! touched columns. The result is exactly orthonormal (`ZᵀZ = I` to round-off) and as well
//! conditioned as a basis can be; the rank decision uses the singular values.

use faer::Mat;

use crate::error::{MultibodyError, Result};
use crate::structure::ConstraintMatrix;

/// The null-space basis and what the SVD found.
#[derive(Clone, Debug)]
pub struct NullSpace {
    /// `Z`: `cols × (cols − rank)`, orthonormal columns spanning `{X : G X = 0}`. Columns: first
    /// the unit vectors of the untouched columns (ascending), then the SVD part.
    pub basis: Mat<f64>,
    /// Rank of `G`.
    pub rank: usize,
    /// Singular values of `G` (on its touched columns), descending.
    pub singular_values: Vec<f64>,
    /// Largest `|G Z|` entry (a check; round-off).
    pub residual: f64,
}

/// Relative singular-value threshold for the rank of `G` (entries are O(1) direction cosines).
pub const RANK_TOLERANCE: f64 = 1e-10;

/// `Z` for a constraint matrix. Errors if `G` has dependent rows (redundant constraints),
/// naming the rows' owners.
pub fn null_space(g: &ConstraintMatrix) -> Result<NullSpace> {
    let mut touched = vec![false; g.cols];
    for &(_, c, v) in &g.entries {
        if v != 0.0 {
            touched[c] = true;
        }
    }
    let cols_s: Vec<usize> = (0..g.cols).filter(|&c| touched[c]).collect();
    let mut pos = vec![usize::MAX; g.cols];
    for (i, &c) in cols_s.iter().enumerate() {
        pos[c] = i;
    }
    let ns = cols_s.len();
    let mut gs = Mat::<f64>::zeros(g.rows, ns);
    for &(r, c, v) in &g.entries {
        if v != 0.0 {
            gs[(r, pos[c])] += v;
        }
    }
    let (sv, v_s, u_s) = if ns > 0 && g.rows > 0 {
        let svd = gs.svd().map_err(|e| MultibodyError::LinearSolve(format!("SVD of G: {e:?}")))?;
        let s: Vec<f64> = (0..g.rows.min(ns)).map(|i| svd.S()[i]).collect();
        (s, svd.V().to_owned(), svd.U().to_owned())
    } else {
        (Vec::new(), Mat::zeros(ns, ns), Mat::zeros(g.rows, g.rows))
    };
    let smax = sv.first().copied().unwrap_or(0.0);
    let rank = sv.iter().filter(|&&s| s > RANK_TOLERANCE * smax.max(f64::MIN_POSITIVE)).count();
    if rank < g.rows {
        // Left null vectors name the dependent rows.
        let mut owners: Vec<String> = Vec::new();
        for col in rank..g.rows {
            for r in 0..g.rows {
                if u_s[(r, col)].abs() > 1e-6 && !owners.contains(&g.labels[r].owner) {
                    owners.push(g.labels[r].owner.clone());
                }
            }
        }
        return Err(MultibodyError::RedundantConstraints {
            deficiency: g.rows - rank,
            involved: owners.join(", "),
        });
    }
    let n_free = g.cols - ns;
    let mut z = Mat::<f64>::zeros(g.cols, n_free + ns - rank);
    let mut col = 0;
    for c in 0..g.cols {
        if !touched[c] {
            z[(c, col)] = 1.0;
            col += 1;
        }
    }
    for j in rank..ns {
        // deterministic sign: largest-magnitude entry positive
        let mut big = 0.0f64;
        for i in 0..ns {
            if v_s[(i, j)].abs() > big.abs() + 1e-12 {
                big = v_s[(i, j)];
            }
        }
        let sign = if big < 0.0 { -1.0 } else { 1.0 };
        for i in 0..ns {
            z[(cols_s[i], col)] = sign * v_s[(i, j)];
        }
        col += 1;
    }
    let residual = if ns > 0 {
        let gz = &gs * {
            let mut zs = Mat::<f64>::zeros(ns, ns - rank);
            for j in 0..ns - rank {
                for i in 0..ns {
                    zs[(i, j)] = v_s[(i, rank + j)];
                }
            }
            zs
        };
        let mut m = 0.0f64;
        for j in 0..gz.ncols() {
            for i in 0..gz.nrows() {
                m = m.max(gz[(i, j)].abs());
            }
        }
        m
    } else {
        0.0
    };
    Ok(NullSpace { basis: z, rank, singular_values: sv, residual })
}
