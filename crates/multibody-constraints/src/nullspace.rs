//! An orthonormal basis `Z` of the null space of a structure's constraint rows `G` (eq. 32:
//! `X = Z X_p`, `G Z = 0`), with redundant constraints named by their owners.
//!
//! The basis is [`intrinsic_beam::null_space`] (unit vectors on the columns `G` does not touch,
//! a dense SVD on the rest); this module adds the structure's view: the rank tolerance for
//! `G`'s direction-cosine entries and the error naming the joints whose rows are dependent.

use intrinsic_beam::NullSpace;

use crate::error::{MultibodyError, Result};
use crate::structure::ConstraintMatrix;

/// Relative singular-value threshold for the rank of `G` (entries are O(1) direction cosines).
pub const RANK_TOLERANCE: f64 = 1e-10;

/// `Z` for a constraint matrix. Errors if `G` has dependent rows (redundant constraints),
/// naming the rows' owners.
///
/// ```
/// use intrinsic_beam::Section;
/// use multibody_constraints::{null_space, samples};
///
/// // the paper's 2D two-link: Z spans the motions the joints allow, G Z = 0
/// let structure = samples::paper_2d(Section::paper_2d(), 4, 0.0)?;
/// let g = structure.constraint_matrix();
/// let z = null_space(&g)?;
/// assert_eq!(z.basis.nrows(), structure.dim());
/// assert!(z.residual < 1e-12);
/// # Ok::<(), multibody_constraints::MultibodyError>(())
/// ```
pub fn null_space(g: &ConstraintMatrix) -> Result<NullSpace> {
    let ns = intrinsic_beam::null_space(g.to_dense().as_ref(), RANK_TOLERANCE)?;
    if ns.rank < g.rows {
        // Left null vectors name the dependent rows.
        let mut owners: Vec<String> = Vec::new();
        for col in 0..ns.dependent_rows.ncols() {
            for r in 0..g.rows {
                if ns.dependent_rows[(r, col)].abs() > 1e-6 && !owners.contains(&g.labels[r].owner)
                {
                    owners.push(g.labels[r].owner.clone());
                }
            }
        }
        return Err(MultibodyError::RedundantConstraints {
            deficiency: g.rows - ns.rank,
            involved: owners.join(", "),
        });
    }
    Ok(ns)
}
