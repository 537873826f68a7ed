//! Candidate rigid-body velocity fields that fix the rigid-mode basis (theory.md §4).
//!
//! The rigid eigenspace is degenerate; its basis is fixed by projecting, in order, the rigid
//! rotations of the structure: about the root support first, then joint by joint from the
//! root, the rotation of everything outboard of the joint, e2 axis before e3 (theory.md §4).

use crate::error::{invalid, Result};
use crate::layout::Layout;
use faer::Mat;
use intrinsic_beam::rotation::rotation;
use nalgebra::Vector3;

/// A rigid rotation of a set of beams about an axis through a pivot (global frame).
#[derive(Clone, Debug, PartialEq)]
pub struct RigidRotation {
    /// A point on the axis.
    pub pivot: [f64; 3],
    /// Axis direction (any non-zero length).
    pub axis: [f64; 3],
    /// Beams that rotate (the others stay at rest).
    pub beams: Vec<usize>,
}

/// The velocity fields `X1` (n1 × count) of the given rigid rotations at the reference
/// configuration: at each node of a moving beam `ω_local = T̄ᵀ a`, `v_local = T̄ᵀ (a × (r̄ − p))`.
/// Planar layouts keep the active components `v1, v3, ω2`.
pub fn rigid_rotation_fields(layout: &Layout, rotations: &[RigidRotation]) -> Result<Mat<f64>> {
    let comps = layout.components;
    let mut out = Mat::<f64>::zeros(layout.n1(), rotations.len());
    for (col, rot) in rotations.iter().enumerate() {
        let a = Vector3::from_column_slice(&rot.axis);
        if !(a.norm().is_finite() && a.norm() > 0.0) {
            return Err(invalid(
                format!("rotations[{col}].axis"),
                format!("{:?}", rot.axis),
                "must be finite and non-zero",
            ));
        }
        let a = a.normalize();
        let p = Vector3::from_column_slice(&rot.pivot);
        for &b in &rot.beams {
            if b >= layout.beams.len() {
                return Err(invalid(
                    format!("rotations[{col}].beams"),
                    b,
                    format!("the layout has {} beams", layout.beams.len()),
                ));
            }
            let beam = &layout.beams[b];
            for n in 0..beam.n_nodes() {
                let t = rotation(&beam.xi(n));
                let w = t.transpose() * a;
                let v = t.transpose() * a.cross(&(beam.position(n) - p));
                let full = [v.x, v.y, v.z, w.x, w.y, w.z];
                for c in 0..comps.k() {
                    out[(layout.x1_index(b, n, c), col)] = full[comps.spatial_index(c)];
                }
            }
        }
    }
    Ok(out)
}

/// The candidate list for a serial chain whose beams are in order from the root: for each
/// joint `j` (0 = root support at the start of beam 0, `j ≥ 1` = joint between beams
/// `j−1` and `j`, at the start of beam `j`), a rotation about each of `axes[j]` (global
/// directions, in priority order) of beams `j…end`.
pub fn chain_rotations(layout: &Layout, axes: &[Vec<[f64; 3]>]) -> Result<Vec<RigidRotation>> {
    let nb = layout.beams.len();
    if axes.len() > nb {
        return Err(invalid("axes", axes.len(), format!("a chain of {nb} beams has {nb} joints")));
    }
    let mut out = Vec::new();
    for (j, list) in axes.iter().enumerate() {
        let pivot = layout.beams[j].reference_positions[0];
        for axis in list {
            out.push(RigidRotation { pivot, axis: *axis, beams: (j..nb).collect() });
        }
    }
    Ok(out)
}
