//! Commanded joint rotations (reconfiguration): a rotation of a joint or of the root support
//! about a fixed axis, held or ramped to its target, and the controller references they give.
//!
//! A command on joint `j` prescribes its relative rotation `ξ_j,r(t) = q(a, θ(t)) ⊗ ξ̄_j` (axis
//! `a` in the joint's first end frame, `ξ̄_j` the reference relative rotation); a command on
//! the root support prescribes the supported node's orientation `ξ_root,r(t) = q(a, θ(t)) ⊗
//! ξ̄_root` (axis global). `q(a, θ) = (cos θ/2, sin θ/2 a/|a|)` (eq. 9). The angle stays 0
//! until `start_s`, then ramps to its target `θ_f` within `ramp_s` with a smooth step,
//!
//! ```text
//!   θ(t) = θ_f (3τ² − 2τ³),   τ = clamp((t − start_s) / ramp_s, 0, 1)
//! ```
//!
//! (`θ = θ_f` from `start_s` on when `ramp_s = 0`; zero rate at both ends of the ramp, so the
//! command itself excites no vibration step). Staggered starts order the motions: with joints
//! rigid in torsion about each end's own axis (the universal joint, theory.md §3) the relative
//! rotation reached depends on the path, not only on its end (the torsion constraint is not
//! integrable), so the order in which a root and an elbow command move matters.
//! The exact-joints cost (theory.md §10.8) measures the joint and root quaternion states
//! against these references directly. Each plan's reference follows the command over the
//! horizon: the stage cost of the shooting node at time `t_0 + kΔt` (`t_0` the plan's start)
//! measures the state against the command at that time ([`ReferenceSchedule::nodes`],
//! `ocp_transcription::Ocp::x_ref_nodes`), so a plan anticipates the ramp instead of chasing
//! the command of its start.

use crate::error::{invalid, Result};
use intrinsic_beam::rotation::{axis_angle, quat_mul};
use nalgebra::{Vector3, Vector4};
use serde::{Deserialize, Serialize};

/// A commanded rotation of one joint or of the root support.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointCommand {
    /// Joint or support name.
    pub joint: String,
    /// Rotation axis (any non-zero length): in the joint's first end frame, or global for a
    /// support.
    pub axis: [f64; 3],
    /// Target angle (deg).
    pub angle_deg: f64,
    /// Time to reach the target from 0 (s), from `start_s` on; 0: a step at `start_s`.
    pub ramp_s: f64,
    /// Time the ramp starts (s); the angle is 0 before it. Default 0.
    #[serde(default)]
    pub start_s: f64,
}

impl JointCommand {
    /// Checks the values (errors name `axis`, `angle_deg`, `ramp_s`, `start_s`); the joint name is
    /// checked against the structure by [`crate::Scenario::validate`].
    pub fn validate(&self) -> Result<()> {
        if self.joint.trim().is_empty() {
            return Err(invalid("joint", "\"\"", "must name a joint or support"));
        }
        let n = Vector3::from(self.axis).norm();
        if !(n.is_finite() && n > 0.0) {
            return Err(invalid("axis", format!("{:?}", self.axis), "must be finite and non-zero"));
        }
        if !self.angle_deg.is_finite() || self.angle_deg.abs() > 180.0 {
            return Err(invalid("angle_deg", self.angle_deg, "must be finite, in [-180, 180]"));
        }
        if !(self.ramp_s.is_finite() && self.ramp_s >= 0.0) {
            return Err(invalid("ramp_s", self.ramp_s, "must be finite and ≥ 0"));
        }
        if !(self.start_s.is_finite() && self.start_s >= 0.0) {
            return Err(invalid("start_s", self.start_s, "must be finite and ≥ 0"));
        }
        Ok(())
    }

    /// Commanded angle at time `t` (rad), the smooth ramp of the module docs.
    pub fn angle_at(&self, t: f64) -> f64 {
        let target = self.angle_deg.to_radians();
        let t = t - self.start_s;
        if self.ramp_s <= 0.0 {
            return if t >= 0.0 { target } else { 0.0 };
        }
        let tau = (t / self.ramp_s).clamp(0.0, 1.0);
        target * tau * tau * (3.0 - 2.0 * tau)
    }

    /// The commanded rotation `q(a, θ(t))` at time `t`.
    pub fn rotation_at(&self, t: f64) -> Vector4<f64> {
        let a = Vector3::from(self.axis);
        axis_angle(&(a / a.norm()), self.angle_at(t))
    }

    /// The commanded quaternion `q(a, θ(t)) ⊗ base` (`base`: the reference relative rotation
    /// of a joint, or the reference orientation of the supported node).
    pub fn quaternion_at(&self, t: f64, base: &Vector4<f64>) -> Vector4<f64> {
        quat_mul(&self.rotation_at(t), base)
    }
}

/// Rotation angle `2 acos|⟨a, b⟩|` between two unit quaternions (rad): the angle of the
/// rotation taking one to the other, sign of the quaternions ignored.
pub fn quaternion_distance(a: &Vector4<f64>, b: &Vector4<f64>) -> f64 {
    let d = a.dot(b) / (a.norm() * b.norm());
    2.0 * d.abs().min(1.0).acos()
}

/// Where a command acts: the joint's nodes (global node indices; one for a support) and its
/// reference rotation (relative rotation of a joint, orientation of a support's node), from
/// the joints' names and nodes (structure order) and the reference node quaternions.
pub(crate) fn command_target(
    joint_names: &[String],
    joint_nodes: &[Vec<usize>],
    reference_xi: &[Vector4<f64>],
    command: &JointCommand,
) -> Result<(Vec<usize>, Vector4<f64>)> {
    let j = joint_names
        .iter()
        .position(|n| *n == command.joint)
        .ok_or_else(|| invalid("joint", &command.joint, "no such joint or support"))?;
    let nodes = joint_nodes[j].clone();
    let base = match nodes.as_slice() {
        [n] => reference_xi[*n],
        [a, b] => relative_quaternion(&reference_xi[*a], &reference_xi[*b]),
        _ => return Err(invalid("joint", &command.joint, "must join two ends or be a support")),
    };
    Ok((nodes, base))
}

/// Per command, the rotation angle (rad) between the commanded rotation at time `t` and the one
/// of the node quaternions `xi` (global node order); joints as in [`command_target`].
pub(crate) fn command_errors(
    commands: &[JointCommand],
    joint_names: &[String],
    joint_nodes: &[Vec<usize>],
    reference_xi: &[Vector4<f64>],
    xi: &[Vector4<f64>],
    t: f64,
) -> Vec<f64> {
    commands
        .iter()
        .filter_map(|c| {
            let (nodes, base) = command_target(joint_names, joint_nodes, reference_xi, c).ok()?;
            let actual = match nodes.as_slice() {
                [n] => xi[*n],
                [a, b] => relative_quaternion(&xi[*a], &xi[*b]),
                _ => return None,
            };
            Some(quaternion_distance(&c.quaternion_at(t, &base), &actual))
        })
        .collect()
}

/// `ξ_a* ⊗ ξ_b`.
fn relative_quaternion(a: &Vector4<f64>, b: &Vector4<f64>) -> Vector4<f64> {
    quat_mul(&intrinsic_beam::rotation::quat_conj(a), b)
}

/// The controller's reference state over time: the reference state `x_ref` with the quaternion
/// entries of each command (state offset, command, base rotation) replaced by the command.
#[derive(Clone, Debug)]
pub struct ReferenceSchedule {
    x_ref: Vec<f64>,
    slots: Vec<(usize, JointCommand, Vector4<f64>)>,
}

impl ReferenceSchedule {
    /// The schedule on `x_ref`; `slots`: (offset of the 4 quaternion entries, command, base).
    pub fn new(x_ref: Vec<f64>, slots: Vec<(usize, JointCommand, Vector4<f64>)>) -> Result<Self> {
        if let Some((o, c, _)) = slots.iter().find(|(o, _, _)| o + 4 > x_ref.len()) {
            return Err(invalid(format!("reference of `{}`", c.joint), o, "outside the state"));
        }
        Ok(Self { x_ref, slots })
    }

    /// The reference state at time `t`.
    pub fn at(&self, t: f64) -> Vec<f64> {
        let mut x = self.x_ref.clone();
        for (o, c, base) in &self.slots {
            x[*o..*o + 4].copy_from_slice(c.quaternion_at(t, base).as_slice());
        }
        x
    }

    /// The reference states at the `intervals + 1` shooting nodes of a plan starting at
    /// `start` with intervals of `interval` s: `at(start + k·interval)`, `k = 0 … intervals`.
    pub fn nodes(&self, start: f64, interval: f64, intervals: usize) -> Vec<Vec<f64>> {
        (0..=intervals).map(|k| self.at(start + k as f64 * interval)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_is_smooth_and_reaches_the_target() {
        let c = JointCommand {
            joint: "elbow".into(),
            axis: [0.0, 2.0, 0.0],
            angle_deg: 90.0,
            ramp_s: 4.0,
            start_s: 0.0,
        };
        c.validate().unwrap();
        assert_eq!(c.angle_at(0.0), 0.0);
        assert!((c.angle_at(2.0) - 45f64.to_radians()).abs() < 1e-12);
        assert!((c.angle_at(4.0) - 90f64.to_radians()).abs() < 1e-12);
        assert!((c.angle_at(9.0) - 90f64.to_radians()).abs() < 1e-12);
        // zero rate at both ends
        let h = 1e-6;
        assert!(c.angle_at(h) < 1e-9);
        assert!((c.angle_at(4.0) - c.angle_at(4.0 - h)).abs() < 1e-9);
        let q = c.quaternion_at(4.0, &Vector4::new(1.0, 0.0, 0.0, 0.0));
        let expect = Vector4::new(
            (0.25 * std::f64::consts::PI).cos(),
            0.0,
            (0.25f64 * std::f64::consts::PI).sin(),
            0.0,
        );
        assert!((q - expect).norm() < 1e-12);
        assert!((quaternion_distance(&q, &(-expect)) - 0.0).abs() < 1e-6);
        let held = JointCommand { ramp_s: 0.0, ..c.clone() };
        assert!((held.angle_at(0.0) - 90f64.to_radians()).abs() < 1e-12);
        // a later start shifts the ramp (0 before it, a step at it without a ramp)
        let late = JointCommand { start_s: 1.5, ..c.clone() };
        for t in [0.0, 0.7, 1.5, 2.3, 3.5, 5.5, 9.0] {
            let expect = if t < 1.5 { 0.0 } else { c.angle_at(t - 1.5) };
            assert_eq!(late.angle_at(t), expect, "t = {t}");
        }
        let step = JointCommand { start_s: 1.5, ..held };
        assert_eq!(step.angle_at(1.4), 0.0);
        assert_eq!(step.angle_at(1.5), 90f64.to_radians());
    }

    #[test]
    fn node_references_follow_the_ramp() {
        let c = JointCommand {
            joint: "elbow".into(),
            axis: [0.0, 0.0, 1.0],
            angle_deg: 60.0,
            ramp_s: 4.0,
            start_s: 0.0,
        };
        let base = Vector4::new(1.0, 0.0, 0.0, 0.0);
        let mut x_ref = vec![0.0; 9];
        x_ref[5] = 1.0;
        let s = ReferenceSchedule::new(x_ref.clone(), vec![(5, c.clone(), base)]).unwrap();
        let nodes = s.nodes(1.0, 0.25, 24);
        assert_eq!(nodes.len(), 25);
        for (k, x) in nodes.iter().enumerate() {
            let t = 1.0 + 0.25 * k as f64;
            assert_eq!(x, &s.at(t), "node {k}");
            assert_eq!(&x[..5], &x_ref[..5]);
            let q = Vector4::from_column_slice(&x[5..9]);
            assert!((quaternion_distance(&q, &base) - c.angle_at(t)).abs() < 1e-12);
        }
        // moving within the ramp, constant after it
        assert!(nodes[1][8] > nodes[0][8]);
        assert_eq!(nodes[12], nodes[24]);
        assert!(ReferenceSchedule::new(x_ref, vec![(6, c, base)]).is_err());
    }

    #[test]
    fn validate_names_the_field() {
        let ok = JointCommand {
            joint: "root".into(),
            axis: [0.0, 0.0, 1.0],
            angle_deg: 30.0,
            ramp_s: 0.0,
            start_s: 0.0,
        };
        ok.validate().unwrap();
        let cases: [(&str, JointCommand); 7] = [
            ("joint", JointCommand { joint: " ".into(), ..ok.clone() }),
            ("axis", JointCommand { axis: [0.0; 3], ..ok.clone() }),
            ("axis", JointCommand { axis: [f64::NAN, 0.0, 1.0], ..ok.clone() }),
            ("angle_deg", JointCommand { angle_deg: 200.0, ..ok.clone() }),
            ("ramp_s", JointCommand { ramp_s: -1.0, ..ok.clone() }),
            ("start_s", JointCommand { start_s: -0.5, ..ok.clone() }),
            ("start_s", JointCommand { start_s: f64::INFINITY, ..ok.clone() }),
        ];
        for (field, c) in cases {
            match c.validate() {
                Err(crate::MpcError::Invalid { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {other:?}"),
            }
        }
    }
}
