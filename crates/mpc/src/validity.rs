//! The controller model's range of validity: joint angles between links predicted by the
//! augmented modal model (29) from its quaternion states, for checking NMPC plans.
//!
//! The modes are computed at the 0° joint reference angle (paper §5.2), so the reduced model
//! describes the structure only while the joints stay near that angle ("the joint angle might
//! be no longer in the range of validity of the model", §5.2). A plan whose predicted joint
//! angle leaves a limit is therefore a plan the plant will not follow (docs/mpc.md measures
//! the FE/ROM mismatch), and the controller can treat it as a failed attempt.

use crate::error::{invalid, Result};
use crate::plant::relative_angle;
use crate::scenario::Setup;
use nalgebra::{DVector, Matrix4xX, Vector4};

/// Joint angles between links as functions of the modal state `q_a`: the quaternion field at
/// each joint's two end nodes is `ξ(n) = Φξ(n) qξ` (theory.md §6; the reconstruction the
/// closed loop uses for its records with the modal plant), and the joint angle is the
/// relative rotation of the two ends minus that of the reference configuration.
#[derive(Clone, Debug)]
pub struct JointMonitor {
    /// Per joint between links: `(Φξ at end a, Φξ at end b, reference relative angle)`.
    joints: Vec<(Matrix4xX<f64>, Matrix4xX<f64>, f64)>,
    /// Offset of `qξ` in `q_a`.
    offset: usize,
    /// Signed planar angle about this local axis, or the spatial rotation angle.
    planar_axis: Option<usize>,
}

impl JointMonitor {
    /// The joints between links of `setup`'s structure (supports are not monitored: the root
    /// rotation is a rigid-body motion the model represents at any angle).
    pub fn new(setup: &Setup) -> Result<Self> {
        let qm = setup.rom.quaternion().ok_or_else(|| {
            invalid("rom", "without quaternion states", "joint angles need the augmented model")
        })?;
        let nxi = qm.kept.len();
        let rows = |n: usize| Matrix4xX::from_fn(nxi, |a, c| qm.phi_xi[(4 * n + a, c)]);
        let mut joints = Vec::new();
        for nodes in setup.joint_nodes.iter().filter(|n| n.len() == 2) {
            let (a, b) = (nodes[0], nodes[1]);
            if a >= qm.weights.len() || b >= qm.weights.len() {
                return Err(invalid("joint node", a.max(b), "outside the model's nodes"));
            }
            let rel0 =
                relative_angle(&setup.reference_xi[a], &setup.reference_xi[b], setup.planar_axis);
            joints.push((rows(a), rows(b), rel0));
        }
        Ok(Self { joints, offset: setup.rom.xi_offset(), planar_axis: setup.planar_axis })
    }

    /// Number of monitored joints.
    pub fn len(&self) -> usize {
        self.joints.len()
    }

    /// Whether no joint is monitored (a single link).
    pub fn is_empty(&self) -> bool {
        self.joints.is_empty()
    }

    /// Largest `|joint angle|` (rad) of the state `q` (length of the augmented state);
    /// non-finite states give `+∞` (never a silent NaN: such a plan is out of range).
    pub fn max_angle(&self, q: &[f64]) -> f64 {
        let nxi = self.joints.first().map_or(0, |j| j.0.ncols());
        if q.len() < self.offset + nxi {
            return f64::INFINITY;
        }
        let qxi = DVector::from_column_slice(&q[self.offset..self.offset + nxi]);
        let mut worst = 0.0f64;
        for (pa, pb, rel0) in &self.joints {
            let xa: Vector4<f64> = pa * &qxi;
            let xb: Vector4<f64> = pb * &qxi;
            if xa.norm() == 0.0 || xb.norm() == 0.0 {
                return f64::INFINITY;
            }
            let angle = (relative_angle(&xa, &xb, self.planar_axis) - rel0).abs();
            if !angle.is_finite() {
                return f64::INFINITY;
            }
            worst = worst.max(angle);
        }
        worst
    }

    /// Largest `|joint angle|` (rad) over a plan's state nodes.
    pub fn plan_max_angle(&self, states: &[DVector<f64>]) -> f64 {
        states.iter().map(|s| self.max_angle(s.as_slice())).fold(0.0, f64::max)
    }
}
