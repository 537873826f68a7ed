//! The exact-joints reduced model (theory.md §10): the modal model of (14)–(21) on per-link
//! fields, with each joint's relative rotation a state and velocity compatibility (11)
//! imposed at the current relative rotation.
//!
//! * [`LinkBasis`]: velocity and force fields supported on one link each, in local
//!   components, orthonormal (theory.md §10.2).
//! * Joint rows `A(ξ) q1 = 0`, linear in each joint's relative rotation matrix (theory.md §10.3).
//! * [`ExactJointsRom`]: `q1 = Z(ξ) p` with `Z` an orthonormal basis of `null A(ξ)` that moves
//!   smoothly from a reference basis `Z0`; `ṗ = Zᵀf − ZᵀŻ p`, the reactions `Aᵀλ` eliminated
//!   (`ZᵀAᵀ = 0`), `ZᵀŻ` skew so the energy `½|p|² + ½|p2|²` is conserved exactly; joint and
//!   root quaternions advanced with the model's own body rates (theory.md §10.4–10.5).
//!
//! With the paper's constrained modes as fields and `Z0` their coordinates
//! ([`paper_reduction`]), the model at the reference joint rotations is the paper's model
//! (14)–(21) (same right-hand side and `(q1, q2, u)` Jacobian), because `A(ξ̄) Z0 = 0` makes
//! `Z = Z0` and `ZᵀŻ = 0` there.

mod ambient;
mod columns;
mod eval;
mod frame;
mod jacobian;
mod model;
mod planar;
mod rows;
mod unit_rotation;

#[cfg(test)]
mod tests;

pub use ambient::{LinkBasis, LinkBasisSettings};
pub use model::ExactJointsRom;
pub use rows::relative_quaternion;

use crate::basis::ModalBasis;
use crate::error::Result;
use crate::rom::Input;
use crate::structure::StructureModel;
use faer::Mat;
use multibody_constraints::Structure;

/// The exact-joints model on the paper's basis: link fields = per-link pieces of the selected
/// constrained modes `modes` (no added rigid link motions), force fields = per-link pieces of
/// the elastic modes' `Φ2`, `Z0` = the modes' coordinates on them, `Z2` = the elastic modes'
/// force coordinates (both exact re-expansions, to round-off). At the reference rotations it equals
/// the paper's [`crate::ModalRom`] on `modes` without quaternion states.
pub fn paper_reduction(
    structure: &Structure,
    model: &StructureModel,
    modes: &ModalBasis,
    damping: Option<&Mat<f64>>,
    inputs: &[Input],
) -> Result<ExactJointsRom> {
    let settings = LinkBasisSettings { rigid_links: false, ..LinkBasisSettings::default() };
    let el: Vec<usize> = (modes.n_rigid()..modes.n_modes()).collect();
    let phi2 = Mat::from_fn(modes.phi2().nrows(), el.len(), |i, j| modes.phi2()[(i, el[j])]);
    let basis =
        LinkBasis::from_fields_and_forces(model, &[modes.phi1()], Some(phi2.as_ref()), &settings)?;
    let z0 = basis.coordinates1(modes.phi1());
    let z2 = basis.coordinates2(phi2.as_ref());
    ExactJointsRom::with_coordinates(structure, basis, damping, inputs, z0, z2)
}

/// The exact-joints model on link fields built from `fields` (structure fields, e.g.
/// constrained modes at several reference angles) with all motions compatible at the
/// reference rotations.
pub fn from_fields(
    structure: &Structure,
    model: &StructureModel,
    fields: &[faer::MatRef<'_, f64>],
    settings: &LinkBasisSettings,
    damping: Option<&Mat<f64>>,
    inputs: &[Input],
) -> Result<ExactJointsRom> {
    let basis = LinkBasis::from_fields(model, fields, settings)?;
    ExactJointsRom::new(structure, basis, damping, inputs)
}
