//! The root link's orientation by its chord, an alternative to the root node's rotation used
//! by the stabilisation criterion ([`crate::RunSummary::orientation_error_deg`]).
//!
//! For a flexible link hinged at the root, the root *node*'s rotation is the link's rigid
//! orientation plus the local bending slope at the hinge: the slope from the root follower
//! moments themselves (a moment `M` tilts the root of a link of stiffness `EI` and length `L`
//! by ≈ `M L / (3 EI)`, 4° for `M` = 0.2 in the paper's 3D section) and from bending
//! vibration. In the 3D two-link (docs/mpc.md) that contribution is 5–7° at the end
//! of the runs at ω0 = 1 while the chord has returned to 3–4°. The chord (first node → last
//! node of the root link) measures where the link points, not how its root is bent.

use crate::closed_loop::Snapshot;
use crate::error::{invalid, Result};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Orientation of the root link's chord relative to its direction in the first snapshot.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChordOrientation {
    /// Time of the last snapshot (s).
    pub t_final: f64,
    /// Chord angle at the last snapshot (deg).
    pub final_deg: f64,
    /// Largest chord angle over the snapshots (deg; sampled every snapshot interval, so at
    /// most the true excursion).
    pub max_deg: f64,
}

impl ChordOrientation {
    /// The stabilisation criterion's orientation condition read on the chord: back within
    /// `fraction` (0.2) of its largest excursion.
    pub fn within(&self, fraction: f64) -> bool {
        self.final_deg <= fraction * self.max_deg
    }
}

/// Angle (rad) between the chords `a` and `b`.
fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    // atan2 of the cross and dot products: accurate at small and large angles alike
    a.cross(b).norm().atan2(a.dot(b))
}

/// The chord orientation of beam `beam` (the root link: 0) over `snapshots` (positions per
/// beam per node, as recorded by [`crate::run`]), relative to its chord in the first
/// snapshot (the reference configuration at t = 0).
///
/// Errors: no snapshots, no such beam or fewer than two nodes, or a chord of zero or
/// non-finite length.
pub fn chord_orientation(snapshots: &[Snapshot], beam: usize) -> Result<ChordOrientation> {
    let chord = |s: &Snapshot| -> Result<Vector3<f64>> {
        let nodes = s.positions.get(beam).ok_or_else(|| {
            invalid("beam", beam, format!("the snapshot at t = {} has no such beam", s.t))
        })?;
        if nodes.len() < 2 {
            return Err(invalid("beam", beam, "needs at least two nodes"));
        }
        let d = Vector3::from(nodes[nodes.len() - 1]) - Vector3::from(nodes[0]);
        let n = d.norm();
        if !(n.is_finite() && n > 0.0) {
            return Err(invalid(
                "chord length",
                n,
                format!("at t = {}: must be finite and > 0", s.t),
            ));
        }
        Ok(d)
    };
    let first = snapshots.first().ok_or_else(|| invalid("snapshots", 0, "none recorded"))?;
    let c0 = chord(first)?;
    let mut max_deg = 0.0f64;
    let mut final_deg = 0.0;
    for s in snapshots {
        let a = angle(&c0, &chord(s)?).to_degrees();
        max_deg = max_deg.max(a);
        final_deg = a;
    }
    let t_final = snapshots[snapshots.len() - 1].t;
    Ok(ChordOrientation { t_final, final_deg, max_deg })
}
