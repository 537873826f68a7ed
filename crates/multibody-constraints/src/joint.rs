//! Joints and supports: kinds, per-direction freedoms, and their rows (11)–(12).
//!
//! A joint ties the ends `j = 0…n−1` of `n ≥ 2` beams; a support ties one end to the ground.
//! Each kind is turned into three translation and three rotation *axes*, each rigid or free
//! (theory.md §3). For an axis with unit vector `u_j` (in end `j`'s local components):
//!
//! * rigid: compatibility `u_j·x_j = u_0·x_0` for `j ≥ 1` (support: `u_0·x_0 = 0`) and the
//!   balance `Σ_j σ_j u_j·y_j = 0` (joints only; the ground takes a support's reaction);
//! * free: `u_j·y_j = −σ_j τ_j` for every end (`τ_j` an applied joint torque, usually 0),
//!
//! where `x_j` is the end node's velocity part (`v` or `ω`), `y_j` the end's boundary value
//! (`f` or `m`) and `σ_j = +1` at `s = 0`, `−1` at `s = L` (eq. 12 and Fig. 2). Per axis that is
//! `n` rows, so a joint closes exactly its `n·k` end unknowns. Because the axes of each end form
//! an orthonormal triad, `Σ_j σ_j x_jᵀ y_j = 0` whenever the rows hold: joints do no work.
//!
//! The axes may be fixed in the global frame ([`Frame::Global`]), attached to the local frame
//! of one of the joint's ends ([`Frame::End`], e.g. a hinge axis carried by the parent link),
//! or taken in each end's own frame ([`Frame::EachEnd`], the torsion of the paper's
//! universal/wheel joint, §5.3: `ω1^a = ω1^b`, `m1^a = m1^b`, bending moments zero).

use crate::error::{MultibodyError, Owner, Result};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Which end of a beam: `s = 0` or `s = L`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum End {
    /// The end at `s = 0`.
    Start,
    /// The end at `s = L`.
    End,
}

impl End {
    /// `σ = +1` at `s = 0`, `−1` at `s = L`: the sign of the end's force in the balance (12).
    pub fn sign(self) -> f64 {
        match self {
            End::Start => 1.0,
            End::End => -1.0,
        }
    }

    /// `start` or `end`.
    pub fn name(self) -> &'static str {
        match self {
            End::Start => "start",
            End::End => "end",
        }
    }

    /// Parses `start`/`0` or `end`/`L`; `owner` names the joint in the error.
    pub fn parse(owner: &Owner, text: &str) -> Result<Self> {
        match text.trim() {
            "start" | "0" | "s=0" => Ok(End::Start),
            "end" | "L" | "s=L" => Ok(End::End),
            other => {
                Err(MultibodyError::UnknownEnd { owner: owner.clone(), end: other.to_string() })
            }
        }
    }
}

/// A beam end, by beam name.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct EndRef {
    /// Name of the beam.
    pub beam: String,
    /// Which end.
    pub end: End,
}

impl EndRef {
    /// Convenience constructor.
    pub fn new(beam: impl Into<String>, end: End) -> Self {
        Self { beam: beam.into(), end }
    }
}

/// Rigid (motion transmitted, reaction carried) or free (no reaction) along one axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Freedom {
    /// Velocities continuous (or zero against the ground), forces balance.
    Rigid,
    /// Each end's force/moment along the axis is zero (or the applied torque).
    Free,
}

/// The frame in which a joint's axes are given.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Frame {
    /// Fixed in the global (inertial) frame.
    Global,
    /// Attached to the local frame of the joint's `i`-th end (0-based, in the order the joint
    /// lists its ends); for a support, `End(0)` is the supported end.
    End(usize),
    /// Each end's own local frame (the same local components at every end).
    EachEnd,
}

/// The kinds of joints and supports (theory.md §3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum JointKind {
    /// Rigid in every translation and rotation.
    Weld,
    /// Translations rigid, rotations free.
    Ball,
    /// Translations rigid, rotation free about `axis`, rigid about the two perpendicular axes.
    Hinge {
        /// The hinge axis (any non-zero length).
        axis: [f64; 3],
        /// Frame of `axis`. A hinge between links usually carries its axis with the first
        /// (parent) end, `Frame::End(0)`; a hinge to the ground, `Frame::Global`.
        frame: Frame,
    },
    /// The paper's double universal (wheel) joint, §5.3: translations rigid, torsion (each
    /// end's local `e1`) rigid, both bending rotations (local `e2`, `e3`) free.
    Universal,
    /// Rigid or free per direction, for translations and rotations separately.
    Custom {
        /// Freedoms along the three translation axes of `translation_frame`.
        translation: [Freedom; 3],
        /// Frame of the translation axes.
        translation_frame: Frame,
        /// Freedoms about the three rotation axes of `rotation_frame`.
        rotation: [Freedom; 3],
        /// Frame of the rotation axes.
        rotation_frame: Frame,
        /// The three axes (columns: directions in their frame), for both translations and
        /// rotations; `None`: the frame's own `e1, e2, e3`. Must be orthonormal.
        #[serde(default)]
        axes: Option<[[f64; 3]; 3]>,
    },
}

impl JointKind {
    /// A hinge about a global axis (typical for supports).
    ///
    /// ```
    /// use multibody_constraints::{JointKind, Owner};
    ///
    /// // a hinge about e2: translations and two rotations rigid, rotation about e2 free
    /// let hinge = JointKind::hinge_global([0.0, 1.0, 0.0]);
    /// let axes = hinge.axes(&Owner::Joint("elbow".into()), 2)?;
    /// assert_eq!(axes.len(), 6);
    /// assert!(JointKind::hinge_global([0.0; 3]).axes(&Owner::Joint("bad".into()), 2).is_err());
    /// # Ok::<(), multibody_constraints::MultibodyError>(())
    /// ```
    pub fn hinge_global(axis: [f64; 3]) -> Self {
        JointKind::Hinge { axis, frame: Frame::Global }
    }

    /// A hinge whose axis is carried by the joint's first end.
    pub fn hinge_on_first(axis: [f64; 3]) -> Self {
        JointKind::Hinge { axis, frame: Frame::End(0) }
    }
}

/// A joint between two or more beam ends.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Joint {
    /// Unique name (used in errors and outputs).
    pub name: String,
    /// The ends it ties, in order (the first is the reference end of compatibility rows and of
    /// joint angles).
    pub ends: Vec<EndRef>,
    /// Its kind.
    pub kind: JointKind,
}

/// A support: one beam end tied to the ground.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Support {
    /// Unique name.
    pub name: String,
    /// The supported end.
    pub end: EndRef,
    /// Its kind (the ground is the other side).
    pub kind: JointKind,
}

/// Translation (`v`/`f`) or rotation (`ω`/`m`) part of a 6-component field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// `v` and `f`.
    Linear,
    /// `ω` and `m`.
    Angular,
}

/// One axis of a joint: where it lives, its direction (unit) in that frame, and its freedom.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axis {
    /// Translation or rotation.
    pub part: Part,
    /// Frame of `direction`.
    pub frame: Frame,
    /// Unit vector in `frame`.
    pub direction: Vector3<f64>,
    /// Rigid or free.
    pub freedom: Freedom,
}

impl Axis {
    /// The axis in end `j`'s local components, given every end's rotation `T_j` (local →
    /// global).
    pub fn local_at(&self, j: usize, rotations: &[Matrix3<f64>]) -> Vector3<f64> {
        match self.frame {
            Frame::Global => rotations[j].transpose() * self.direction,
            Frame::End(i) => rotations[j].transpose() * (rotations[i] * self.direction),
            Frame::EachEnd => self.direction,
        }
    }
}

fn unit(owner: &Owner, a: [f64; 3]) -> Result<Vector3<f64>> {
    let v = Vector3::from(a);
    let n = v.norm();
    if !n.is_finite() || n < 1e-12 {
        return Err(MultibodyError::ZeroAxis { owner: owner.clone(), axis: a });
    }
    Ok(v / n)
}

/// Completes a unit vector `a` to a right-handed orthonormal triad `(a, b, c)`; `b` is built
/// from the global axis least aligned with `a` (first one on ties), so the choice is
/// deterministic.
pub fn complete_triad(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let mut k = 0;
    for i in 1..3 {
        if a[i].abs() < a[k].abs() - 1e-14 {
            k = i;
        }
    }
    let e = Vector3::ith(k, 1.0);
    let b = a.cross(&e).normalize();
    let c = a.cross(&b);
    (b, c)
}

fn identity_axes(part: Part, frame: Frame, freedoms: [Freedom; 3]) -> [Axis; 3] {
    [0, 1, 2].map(|i| Axis { part, frame, direction: Vector3::ith(i, 1.0), freedom: freedoms[i] })
}

impl JointKind {
    /// The six axes (three translations, three rotations) of this kind; `owner` names the
    /// joint in errors. `n_ends` bounds `Frame::End(i)`.
    pub fn axes(&self, owner: &Owner, n_ends: usize) -> Result<[Axis; 6]> {
        use Freedom::{Free, Rigid};
        let check_frame = |f: Frame| -> Result<()> {
            match f {
                Frame::End(i) if i >= n_ends => Err(MultibodyError::BadPlacement {
                    beam: owner.to_string(),
                    reason: format!("axis frame refers to end {i}, but it has {n_ends} end(s)"),
                }),
                _ => Ok(()),
            }
        };
        let (t, r) = match self {
            JointKind::Weld => (
                identity_axes(Part::Linear, Frame::Global, [Rigid; 3]),
                identity_axes(Part::Angular, Frame::Global, [Rigid; 3]),
            ),
            JointKind::Ball => (
                identity_axes(Part::Linear, Frame::Global, [Rigid; 3]),
                identity_axes(Part::Angular, Frame::Global, [Free; 3]),
            ),
            JointKind::Universal => (
                identity_axes(Part::Linear, Frame::Global, [Rigid; 3]),
                identity_axes(Part::Angular, Frame::EachEnd, [Rigid, Free, Free]),
            ),
            JointKind::Hinge { axis, frame } => {
                check_frame(*frame)?;
                if *frame == Frame::EachEnd {
                    return Err(MultibodyError::BadPlacement {
                        beam: owner.to_string(),
                        reason: "a hinge axis must be global or attached to one end".into(),
                    });
                }
                let a = unit(owner, *axis)?;
                let (b, c) = complete_triad(&a);
                let ax = |d: Vector3<f64>, freedom| Axis {
                    part: Part::Angular,
                    frame: *frame,
                    direction: d,
                    freedom,
                };
                (
                    identity_axes(Part::Linear, Frame::Global, [Rigid; 3]),
                    [ax(a, Free), ax(b, Rigid), ax(c, Rigid)],
                )
            }
            JointKind::Custom {
                translation,
                translation_frame,
                rotation,
                rotation_frame,
                axes,
            } => {
                check_frame(*translation_frame)?;
                check_frame(*rotation_frame)?;
                let mut t = identity_axes(Part::Linear, *translation_frame, *translation);
                let mut r = identity_axes(Part::Angular, *rotation_frame, *rotation);
                if let Some(cols) = axes {
                    let d: Vec<Vector3<f64>> = cols.iter().map(|c| Vector3::from(*c)).collect();
                    for (i, c) in cols.iter().enumerate() {
                        if !(d[i].norm().is_finite() && d[i].norm() > 1e-12) {
                            return Err(MultibodyError::ZeroAxis {
                                owner: owner.clone(),
                                axis: *c,
                            });
                        }
                    }
                    let m = Matrix3::from_columns(&d);
                    let err = (m.transpose() * m - Matrix3::identity()).amax();
                    if err > 1e-9 {
                        return Err(MultibodyError::BadInput {
                            input: owner.to_string(),
                            reason: format!(
                                "custom axes {cols:?} are not orthonormal (|AᵀA − I| = {err:.1e})"
                            ),
                        });
                    }
                    for i in 0..3 {
                        t[i].direction = d[i];
                        r[i].direction = d[i];
                    }
                }
                (t, r)
            }
        };
        Ok([t[0], t[1], t[2], r[0], r[1], r[2]])
    }

    /// The axes that act in a planar structure (motion in the global e1–e3 plane, rotation
    /// about e2): translation axes in the plane and the rotation axis along e2. An axis that
    /// is neither in nor normal to the plane is an error.
    pub fn planar_axes(&self, owner: &Owner, n_ends: usize) -> Result<Vec<Axis>> {
        if let JointKind::Hinge { axis, .. } = self {
            let a = unit(owner, *axis)?;
            if (a.y.abs() - 1.0).abs() > 1e-12 {
                return Err(MultibodyError::NotPlanar {
                    owner: owner.clone(),
                    what: format!(
                        "hinge axis {axis:?} (a planar hinge turns about e2 = [0, 1, 0])"
                    ),
                });
            }
        }
        let mut out = Vec::with_capacity(3);
        for ax in self.axes(owner, n_ends)? {
            let y = ax.direction.y.abs();
            let in_plane = y < 1e-12;
            let normal = (y - 1.0).abs() < 1e-12;
            if !in_plane && !normal {
                return Err(MultibodyError::NotPlanar {
                    owner: owner.clone(),
                    what: format!(
                        "axis {:?} (neither in the e1–e3 plane nor along e2)",
                        ax.direction.as_slice()
                    ),
                });
            }
            match (ax.part, in_plane) {
                (Part::Linear, true) | (Part::Angular, false) => out.push(ax),
                _ => {}
            }
        }
        debug_assert_eq!(out.len(), 3);
        Ok(out)
    }
}

/// What a constraint row states (for reporting and right-hand sides).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowKind {
    /// `u_j·x_j − u_0·x_0 = 0` (or `u_0·x_0 = 0` against the ground).
    Compatibility,
    /// `Σ σ_j u_j·y_j = 0`.
    Balance,
    /// `u_j·y_j = −σ_j τ_j` at one end.
    Free,
}

/// One term of a row: `coefficient · (part of the field at one end, along a local direction)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Term {
    /// Index of the end within the joint.
    pub end: usize,
    /// `true`: acts on the end node's velocity `x1`; `false`: on the end's boundary value `x2`.
    pub on_velocity: bool,
    /// Translation or rotation part.
    pub part: Part,
    /// Local direction times the coefficient.
    pub direction: Vector3<f64>,
}

/// A constraint row of one joint or support, evaluated at given end rotations.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// What the row states.
    pub kind: RowKind,
    /// Index of the axis (into the active axes of the joint).
    pub axis: usize,
    /// For `Free` rows, the end it acts on (the torque sign depends on it).
    pub end: usize,
    /// The terms.
    pub terms: Vec<Term>,
}

/// The rows of a joint with `signs[j] = σ_j` (empty-ground: `ground = true`, one end) for the
/// active `axes`, given every end's rotation. `n·axes.len()` rows for a joint, `axes.len()`
/// for a support.
pub fn rows(axes: &[Axis], signs: &[f64], ground: bool, rotations: &[Matrix3<f64>]) -> Vec<Row> {
    let n = signs.len();
    let mut out = Vec::with_capacity(n * axes.len());
    for (ai, ax) in axes.iter().enumerate() {
        let u: Vec<Vector3<f64>> = (0..n).map(|j| ax.local_at(j, rotations)).collect();
        match ax.freedom {
            Freedom::Rigid => {
                if ground {
                    out.push(Row {
                        kind: RowKind::Compatibility,
                        axis: ai,
                        end: 0,
                        terms: vec![Term {
                            end: 0,
                            on_velocity: true,
                            part: ax.part,
                            direction: u[0],
                        }],
                    });
                } else {
                    for j in 1..n {
                        out.push(Row {
                            kind: RowKind::Compatibility,
                            axis: ai,
                            end: j,
                            terms: vec![
                                Term { end: j, on_velocity: true, part: ax.part, direction: u[j] },
                                Term { end: 0, on_velocity: true, part: ax.part, direction: -u[0] },
                            ],
                        });
                    }
                    out.push(Row {
                        kind: RowKind::Balance,
                        axis: ai,
                        end: 0,
                        terms: (0..n)
                            .map(|j| Term {
                                end: j,
                                on_velocity: false,
                                part: ax.part,
                                direction: u[j] * signs[j],
                            })
                            .collect(),
                    });
                }
            }
            Freedom::Free => {
                for j in 0..n {
                    out.push(Row {
                        kind: RowKind::Free,
                        axis: ai,
                        end: j,
                        terms: vec![Term {
                            end: j,
                            on_velocity: false,
                            part: ax.part,
                            direction: u[j],
                        }],
                    });
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot(axis: Vector3<f64>, angle: f64) -> Matrix3<f64> {
        nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle)
            .into_inner()
    }

    #[test]
    fn triad_is_orthonormal_and_right_handed() {
        for a in [Vector3::y(), Vector3::new(1.0, 2.0, -0.5).normalize(), Vector3::z()] {
            let (b, c) = complete_triad(&a);
            let m = Matrix3::from_columns(&[a, b, c]);
            assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-14);
            assert!((m.determinant() - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn zero_axis_is_an_error() {
        let err = JointKind::hinge_global([0.0, 0.0, 0.0])
            .axes(&Owner::Joint("root".into()), 1)
            .unwrap_err();
        assert!(matches!(err, MultibodyError::ZeroAxis { .. }), "{err}");
        assert!(err.to_string().contains("root"));
    }

    #[test]
    fn custom_axes_must_be_orthonormal() {
        let kind = JointKind::Custom {
            translation: [Freedom::Free, Freedom::Rigid, Freedom::Rigid],
            translation_frame: Frame::Global,
            rotation: [Freedom::Rigid; 3],
            rotation_frame: Frame::Global,
            axes: Some([[1.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        };
        let err = kind.axes(&Owner::Joint("slider".into()), 2).unwrap_err();
        assert!(
            err.to_string().contains("orthonormal") && err.to_string().contains("slider"),
            "{err}"
        );
    }

    #[test]
    fn planar_hinge_off_e2_is_an_error() {
        let err = JointKind::hinge_global([1.0, 1.0, 0.0])
            .planar_axes(&Owner::Joint("elbow".into()), 2)
            .unwrap_err();
        assert!(matches!(err, MultibodyError::NotPlanar { .. }), "{err}");
        let ok = JointKind::hinge_global([0.0, 1.0, 0.0])
            .planar_axes(&Owner::Joint("elbow".into()), 2)
            .unwrap();
        assert_eq!(ok.len(), 3);
        assert_eq!(ok.iter().filter(|a| a.freedom == Freedom::Free).count(), 1);
    }

    /// Rows hold for a velocity and force field built to satisfy the joint, and then the joint
    /// power `Σ σ_j (v_j·f_j + ω_j·m_j)` vanishes: the identity behind energy conservation.
    #[test]
    fn joint_power_vanishes_when_rows_hold() {
        let rotations = [
            rot(Vector3::new(0.2, 1.0, 0.3), 0.7),
            rot(Vector3::new(-1.0, 0.4, 0.1), 1.9),
            rot(Vector3::z(), -0.4),
        ];
        let signs = [-1.0, 1.0, 1.0];
        for kind in [
            JointKind::Weld,
            JointKind::Ball,
            JointKind::Universal,
            JointKind::hinge_on_first([0.3, -0.2, 1.0]),
            JointKind::Custom {
                translation: [Freedom::Rigid, Freedom::Free, Freedom::Rigid],
                translation_frame: Frame::End(1),
                rotation: [Freedom::Free, Freedom::Rigid, Freedom::Free],
                rotation_frame: Frame::Global,
                axes: None,
            },
            JointKind::Custom {
                translation: [Freedom::Free, Freedom::Rigid, Freedom::Rigid],
                translation_frame: Frame::Global,
                rotation: [Freedom::Rigid, Freedom::Free, Freedom::Rigid],
                rotation_frame: Frame::End(0),
                axes: Some({
                    let r = rot(Vector3::new(1.0, 2.0, 3.0), 0.8);
                    [0, 1, 2].map(|i| [r[(0, i)], r[(1, i)], r[(2, i)]])
                }),
            },
        ] {
            let axes = kind.axes(&Owner::Joint("j".into()), 3).unwrap();
            // Build fields satisfying the rows: for each axis, pick a common velocity V and, for
            // rigid axes, forces balancing; for free axes zero forces.
            let mut v = [[Vector3::zeros(); 3]; 2]; // [part][end]
            let mut f = [[Vector3::zeros(); 3]; 2];
            for (ai, ax) in axes.iter().enumerate() {
                let p = if ax.part == Part::Linear { 0 } else { 1 };
                let common = 0.3 + ai as f64;
                for j in 0..3 {
                    let u = ax.local_at(j, &rotations);
                    let vel = if ax.freedom == Freedom::Rigid {
                        common
                    } else {
                        1.7 * j as f64 - 0.9 * ai as f64
                    };
                    v[p][j] += u * vel;
                }
                if ax.freedom == Freedom::Rigid {
                    // forces along u_j with Σ σ_j c_j = 0: c = (σ0 (a+b), a, b) with σ0 = −1.
                    let (a, b) = (0.4 + ai as f64, -1.3);
                    let c = [a + b, a, b];
                    for j in 0..3 {
                        f[p][j] += ax.local_at(j, &rotations) * c[j];
                    }
                }
            }
            let rows = rows(&axes, &signs, false, &rotations);
            assert_eq!(rows.len(), 18);
            for row in &rows {
                let val: f64 = row
                    .terms
                    .iter()
                    .map(|t| {
                        let p = if t.part == Part::Linear { 0 } else { 1 };
                        let x = if t.on_velocity { v[p][t.end] } else { f[p][t.end] };
                        t.direction.dot(&x)
                    })
                    .sum();
                assert!(val.abs() < 1e-13, "{kind:?} {row:?} {val}");
            }
            let power: f64 =
                (0..3).map(|j| signs[j] * (v[0][j].dot(&f[0][j]) + v[1][j].dot(&f[1][j]))).sum();
            assert!(power.abs() < 1e-12, "{kind:?}: power {power}");
        }
    }
}
