//! The [`Structure`]: beams placed in space, joints between their ends, supports to the ground;
//! topology validation, reference configuration and the global vector layout.
//!
//! Global layout (theory.md §2): the beams' vectors `[x1_0…x1_N, x2_0…x2_{N−1}, x2_L, x2_R]`
//! concatenated in beam order ([`Structure::offset`]). Constraint rows come in the order:
//! joints, supports, free ends; each closes `k` end unknowns per end.

use std::collections::HashMap;

use intrinsic_beam::operators::{halves, join};
use intrinsic_beam::rotation::{axis_angle, quat_conj, quat_mul, rotation};
use intrinsic_beam::{Beam, Components, Kinematics};
use nalgebra::{Matrix3, Vector3, Vector4, Vector6};
use serde::{Deserialize, Serialize};

use crate::error::{MultibodyError, Owner, Result};
use crate::joint::{rows, Axis, End, EndRef, Freedom, Joint, JointKind, Part, RowKind, Support};

/// Where a beam's `s = 0` end sits in the reference configuration.
#[derive(Clone, Debug, PartialEq)]
pub enum Placement {
    /// At `origin` with orientation `quaternion` (scalar first, local → global; normalised).
    At {
        /// Position of the `s = 0` end (global).
        origin: Vector3<f64>,
        /// Orientation of the `s = 0` end.
        quaternion: Vector4<f64>,
    },
    /// At a joint: the `s = 0` end of this beam takes part in `joint`, is placed where the
    /// joint's first end is, with that end's orientation turned by `angle` (rad) about `axis`
    /// (in the first end's local frame) — the reference joint angle.
    Attached {
        /// Name of the joint.
        joint: String,
        /// Rotation axis in the first end's local frame (e.g. the hinge axis).
        axis: [f64; 3],
        /// Reference joint angle (rad).
        angle: f64,
    },
}

impl Placement {
    /// At `origin`, turned by `angle` about the global `axis` (identity: beam along global e1).
    pub fn at(origin: [f64; 3], axis: [f64; 3], angle: f64) -> Self {
        Placement::At {
            origin: Vector3::from(origin),
            quaternion: axis_angle(&Vector3::from(axis), angle),
        }
    }

    /// At the origin along global e1.
    pub fn origin() -> Self {
        Placement::at([0.0; 3], [0.0, 1.0, 0.0], 0.0)
    }
}

/// A beam of a structure: its name, discretisation and placement.
#[derive(Clone, Debug)]
pub struct StructureBeam {
    /// Unique name.
    pub name: String,
    /// Section, mesh and components (from `intrinsic-beam`).
    pub beam: Beam,
    /// Reference placement of its `s = 0` end.
    pub placement: Placement,
}

impl StructureBeam {
    /// Convenience constructor.
    pub fn new(name: impl Into<String>, beam: Beam, placement: Placement) -> Self {
        Self { name: name.into(), beam, placement }
    }
}

/// Options of [`Structure::new`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StructureSettings {
    /// Accept beams that are not connected to each other (default `false`: an error).
    pub allow_disconnected: bool,
    /// Largest distance between a joint's ends in the reference configuration, relative to
    /// the longest beam (default `1e-9`).
    pub placement_tolerance: f64,
}

impl Default for StructureSettings {
    fn default() -> Self {
        Self { allow_disconnected: false, placement_tolerance: 1e-9 }
    }
}

/// A joint or support resolved to beam indices, with its active axes.
#[derive(Clone, Debug)]
pub struct JointInfo {
    /// Name.
    pub name: String,
    /// `true` for a support (one end against the ground).
    pub ground: bool,
    /// `(beam index, end)` of each end, in the joint's order.
    pub ends: Vec<(usize, End)>,
    /// Active axes (six in 3D, three in planar structures).
    pub axes: Vec<Axis>,
    /// `σ_j` of each end.
    pub signs: Vec<f64>,
    /// First constraint row of this joint.
    pub first_row: usize,
    /// Number of constraint rows (`n_ends · k`).
    pub n_rows: usize,
    /// Reference relative rotation (end 0 → end 1) for joints, reference orientation of the
    /// end for supports; joint angles are measured from the identity, i.e. they include it.
    pub reference_relative: Vector4<f64>,
}

impl JointInfo {
    /// Indices (into [`JointInfo::axes`]) of the free rotation axes.
    pub fn free_rotation_axes(&self) -> Vec<usize> {
        self.axes
            .iter()
            .enumerate()
            .filter(|(_, a)| a.part == Part::Angular && a.freedom == Freedom::Free)
            .map(|(i, _)| i)
            .collect()
    }

    /// The free rotation axis a joint torque acts about: `axis` if it is one of the free
    /// rotation axes, else (`None`) the joint's only free rotation axis.
    pub fn free_rotation_axis(&self, axis: Option<usize>) -> Result<usize> {
        let free = self.free_rotation_axes();
        match axis {
            Some(a) if free.contains(&a) => Ok(a),
            None if free.len() == 1 => Ok(free[0]),
            _ => Err(MultibodyError::NotFreeRotationAxis { joint: self.name.clone(), axis, free }),
        }
    }
}

/// Label of a constraint row.
#[derive(Clone, Debug, PartialEq)]
pub struct RowLabel {
    /// Joint, support or `free end of <beam>`.
    pub owner: String,
    /// What the row states (`None` for a free-end row `x2_end = 0`).
    pub kind: Option<RowKind>,
}

/// Beams, joints and supports, validated, with the reference configuration.
#[derive(Clone, Debug)]
pub struct Structure {
    beams: Vec<StructureBeam>,
    components: Components,
    offsets: Vec<usize>,
    dim: usize,
    reference: Vec<Kinematics>,
    joints: Vec<JointInfo>,
    free_ends: Vec<(usize, End, usize)>,
    n_constraint_rows: usize,
    joint_defs: Vec<Joint>,
    support_defs: Vec<Support>,
}

fn end_node(beam: &Beam, end: End) -> usize {
    match end {
        End::Start => 0,
        End::End => beam.n_elements(),
    }
}

impl Structure {
    /// Builds and validates a structure: names unique, ends known and used once, one
    /// component set, placements resolvable and joints closed in the reference
    /// configuration, axes non-zero (and planar where needed), beams connected (unless
    /// allowed). Redundant constraints are found by [`crate::Plant::new`]
    /// (its rank check).
    ///
    /// ```
    /// use intrinsic_beam::{Beam, Components, Mesh, Section};
    /// use multibody_constraints::{
    ///     End, EndRef, Joint, JointKind, Placement, Structure, StructureBeam, StructureSettings,
    ///     Support,
    /// };
    ///
    /// // two links of 4 elements: hinged to the ground at the root, hinged at the elbow (axis e2)
    /// let link = || Beam::new(Section::paper_2d(), Mesh::uniform(0.5, 4)?, Components::Planar);
    /// let hinge = JointKind::hinge_global([0.0, 1.0, 0.0]);
    /// let structure = Structure::new(
    ///     vec![
    ///         StructureBeam::new("link1", link()?, Placement::origin()),
    ///         StructureBeam::new(
    ///             "link2",
    ///             link()?,
    ///             Placement::Attached { joint: "elbow".into(), axis: [0.0, 1.0, 0.0], angle: 0.0 },
    ///         ),
    ///     ],
    ///     vec![Joint {
    ///         name: "elbow".into(),
    ///         ends: vec![EndRef::new("link1", End::End), EndRef::new("link2", End::Start)],
    ///         kind: hinge.clone(),
    ///     }],
    ///     vec![Support { name: "root".into(), end: EndRef::new("link1", End::Start), kind: hinge }],
    ///     StructureSettings::default(),
    /// )?;
    /// assert_eq!(structure.beams().len(), 2);
    /// assert!((structure.reference()[1].r[4].x - 1.0).abs() < 1e-12); // the tip at x = 1
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn new(
        beams: Vec<StructureBeam>,
        joints: Vec<Joint>,
        supports: Vec<Support>,
        settings: StructureSettings,
    ) -> Result<Self> {
        if !(settings.placement_tolerance.is_finite() && settings.placement_tolerance > 0.0) {
            return Err(MultibodyError::BadSetting {
                field: "placement_tolerance",
                value: settings.placement_tolerance,
                reason: "must be positive and finite",
            });
        }
        if beams.is_empty() {
            return Err(MultibodyError::BadInput {
                input: "beams".into(),
                reason: "a structure needs at least one beam".into(),
            });
        }
        let mut index: HashMap<&str, usize> = HashMap::new();
        for (i, b) in beams.iter().enumerate() {
            if index.insert(b.name.as_str(), i).is_some() {
                return Err(MultibodyError::DuplicateName { name: b.name.clone(), what: "beam" });
            }
        }
        let components = beams[0].beam.components();
        for b in &beams {
            if b.beam.components() != components {
                return Err(MultibodyError::BadInput {
                    input: format!("beam `{}`", b.name),
                    reason: format!(
                        "component set {:?} differs from the first beam's {:?}",
                        b.beam.components(),
                        components
                    ),
                });
            }
        }
        let planar = components == Components::Planar;
        let known = beams.iter().map(|b| b.name.as_str()).collect::<Vec<_>>().join(", ");
        let resolve = |owner: &Owner, e: &EndRef| -> Result<(usize, End)> {
            index.get(e.beam.as_str()).map(|&i| (i, e.end)).ok_or_else(|| {
                MultibodyError::UnknownBeam {
                    owner: owner.clone(),
                    beam: e.beam.clone(),
                    known: known.clone(),
                }
            })
        };
        let mut names: HashMap<&str, ()> = HashMap::new();
        for n in
            joints.iter().map(|j| j.name.as_str()).chain(supports.iter().map(|s| s.name.as_str()))
        {
            if names.insert(n, ()).is_some() {
                return Err(MultibodyError::DuplicateName {
                    name: n.to_string(),
                    what: "joint or support",
                });
            }
        }
        // Ends used once.
        let mut used: HashMap<(usize, End), Owner> = HashMap::new();
        let mut resolved_joints = Vec::new();
        let mark = |owner: Owner,
                    be: (usize, End),
                    used: &mut HashMap<(usize, End), Owner>|
         -> Result<()> {
            if let Some(first) = used.get(&be) {
                return Err(MultibodyError::EndUsedTwice {
                    beam: beams[be.0].name.clone(),
                    end: be.1.name().into(),
                    first: first.clone(),
                    second: owner,
                });
            }
            used.insert(be, owner);
            Ok(())
        };
        for j in &joints {
            let owner = Owner::Joint(j.name.clone());
            if j.ends.len() < 2 {
                return Err(MultibodyError::TooFewEnds {
                    joint: j.name.clone(),
                    count: j.ends.len(),
                });
            }
            let ends = j.ends.iter().map(|e| resolve(&owner, e)).collect::<Result<Vec<_>>>()?;
            for &be in &ends {
                mark(owner.clone(), be, &mut used)?;
            }
            let axes = if planar {
                j.kind.planar_axes(&owner, ends.len())?
            } else {
                j.kind.axes(&owner, ends.len())?.to_vec()
            };
            resolved_joints.push((j.name.clone(), false, ends, axes));
        }
        for s in &supports {
            let owner = Owner::Support(s.name.clone());
            let be = resolve(&owner, &s.end)?;
            mark(owner.clone(), be, &mut used)?;
            let axes = if planar {
                s.kind.planar_axes(&owner, 1)?
            } else {
                s.kind.axes(&owner, 1)?.to_vec()
            };
            resolved_joints.push((s.name.clone(), true, vec![be], axes));
        }
        // Connectivity: union-find over beams (+ ground).
        let n_beams = beams.len();
        let mut parent: Vec<usize> = (0..=n_beams).collect();
        fn find(p: &mut [usize], i: usize) -> usize {
            let mut r = i;
            while p[r] != r {
                r = p[r];
            }
            let mut i = i;
            while p[i] != r {
                let next = p[i];
                p[i] = r;
                i = next;
            }
            r
        }
        for (_, ground, ends, _) in &resolved_joints {
            let first = ends[0].0;
            for &(b, _) in ends.iter().skip(1) {
                let (ra, rb) = (find(&mut parent, first), find(&mut parent, b));
                parent[ra] = rb;
            }
            if *ground {
                let (ra, rb) = (find(&mut parent, first), find(&mut parent, n_beams));
                parent[ra] = rb;
            }
        }
        let mut groups: HashMap<usize, Vec<&str>> = HashMap::new();
        for (i, b) in beams.iter().enumerate() {
            let r = find(&mut parent, i);
            groups.entry(r).or_default().push(&b.name);
        }
        if groups.len() > 1 && !settings.allow_disconnected {
            let mut detail: Vec<String> =
                groups.values().map(|g| format!("[{}]", g.join(", "))).collect();
            detail.sort();
            return Err(MultibodyError::NotConnected {
                groups: groups.len(),
                detail: detail.join(" "),
            });
        }
        // Placement.
        let mut reference: Vec<Option<Kinematics>> = vec![None; n_beams];
        let joint_by_name: HashMap<&str, usize> =
            joints.iter().enumerate().map(|(i, j)| (j.name.as_str(), i)).collect();
        loop {
            let mut progress = false;
            let mut pending = false;
            for i in 0..n_beams {
                if reference[i].is_some() {
                    continue;
                }
                let b = &beams[i];
                let start = match &b.placement {
                    Placement::At { origin, quaternion } => {
                        let n = quaternion.norm();
                        if !(n.is_finite() && n > 0.0) || origin.iter().any(|x| !x.is_finite()) {
                            return Err(MultibodyError::BadPlacement {
                                beam: b.name.clone(),
                                reason: format!(
                                    "origin {:?} / quaternion {:?} must be finite and non-zero",
                                    origin.as_slice(),
                                    quaternion.as_slice()
                                ),
                            });
                        }
                        Some((quaternion / n, *origin))
                    }
                    Placement::Attached { joint, axis, angle } => {
                        let bad = |reason: String| MultibodyError::BadPlacement {
                            beam: b.name.clone(),
                            reason,
                        };
                        let &ji = joint_by_name
                            .get(joint.as_str())
                            .ok_or_else(|| bad(format!("unknown joint `{joint}`")))?;
                        let (_, _, ends, _) = &resolved_joints[ji];
                        let pos = ends.iter().position(|&(bb, e)| bb == i && e == End::Start);
                        match pos {
                            None => {
                                return Err(bad(format!(
                                    "its start is not an end of joint `{joint}`"
                                )))
                            }
                            Some(0) => {
                                return Err(bad(format!(
                                "it is the first end of joint `{joint}`; place that one explicitly"
                            )))
                            }
                            _ => {}
                        }
                        if !angle.is_finite() {
                            return Err(bad(format!("angle {angle} is not finite")));
                        }
                        let ax = Vector3::from(*axis);
                        if !(ax.norm().is_finite() && ax.norm() > 1e-12) {
                            return Err(MultibodyError::ZeroAxis {
                                owner: Owner::Placement(b.name.clone()),
                                axis: *axis,
                            });
                        }
                        let (pb, pe) = ends[0];
                        reference[pb].as_ref().map(|k| {
                            let node = end_node(&beams[pb].beam, pe);
                            (quat_mul(&k.xi[node], &axis_angle(&ax, *angle)), k.r[node])
                        })
                    }
                };
                match start {
                    Some((xi0, r0)) => {
                        if planar && (xi0[1].abs() > 1e-12 || xi0[3].abs() > 1e-12) {
                            return Err(MultibodyError::NotPlanar {
                                owner: Owner::Beam(b.name.clone()),
                                what: "its orientation (not a rotation about e2)".into(),
                            });
                        }
                        reference[i] =
                            Some(Kinematics::reference(&b.beam, xi0, r0).map_err(|e| {
                                MultibodyError::BadPlacement {
                                    beam: b.name.clone(),
                                    reason: e.to_string(),
                                }
                            })?);
                        progress = true;
                    }
                    None => pending = true,
                }
            }
            if !pending {
                break;
            }
            if !progress {
                let names: Vec<&str> = (0..n_beams)
                    .filter(|&i| reference[i].is_none())
                    .map(|i| beams[i].name.as_str())
                    .collect();
                return Err(MultibodyError::BadPlacement {
                    beam: names.join(", "),
                    reason: "placements form a cycle (or hang on beams that are never placed)"
                        .into(),
                });
            }
        }
        let reference: Vec<Kinematics> =
            reference.into_iter().map(|k| k.expect("all placed")).collect();
        let longest = beams.iter().map(|b| b.beam.mesh().length()).fold(0.0, f64::max);
        // Layout and rows.
        let mut offsets = Vec::with_capacity(n_beams);
        let mut dim = 0;
        for b in &beams {
            offsets.push(dim);
            dim += b.beam.dim();
        }
        let k = components.k();
        let mut joints_out = Vec::new();
        let mut row = 0;
        for (name, ground, ends, axes) in resolved_joints {
            let pos: Vec<Vector3<f64>> =
                ends.iter().map(|&(b, e)| reference[b].r[end_node(&beams[b].beam, e)]).collect();
            for (j, p) in pos.iter().enumerate().skip(1) {
                let gap = (p - pos[0]).norm();
                if gap > settings.placement_tolerance * longest.max(1.0) {
                    return Err(MultibodyError::BadPlacement {
                        beam: beams[ends[j].0].name.clone(),
                        reason: format!("its {} end is {gap:.3e} away from the other ends of joint `{name}` in the reference configuration", ends[j].1.name()),
                    });
                }
            }
            let xi: Vec<Vector4<f64>> =
                ends.iter().map(|&(b, e)| reference[b].xi[end_node(&beams[b].beam, e)]).collect();
            let reference_relative =
                if ground { xi[0] } else { quat_mul(&quat_conj(&xi[0]), &xi[1]) };
            let n_rows = ends.len() * k;
            joints_out.push(JointInfo {
                name,
                ground,
                signs: ends.iter().map(|e| e.1.sign()).collect(),
                ends,
                axes,
                first_row: row,
                n_rows,
                reference_relative,
            });
            row += n_rows;
        }
        let mut free_ends = Vec::new();
        for b in 0..n_beams {
            for e in [End::Start, End::End] {
                if !used.contains_key(&(b, e)) {
                    free_ends.push((b, e, row));
                    row += k;
                }
            }
        }
        Ok(Self {
            beams,
            components,
            offsets,
            dim,
            reference,
            joints: joints_out,
            free_ends,
            n_constraint_rows: row,
            joint_defs: joints,
            support_defs: supports,
        })
    }

    /// The beams.
    pub fn beams(&self) -> &[StructureBeam] {
        &self.beams
    }

    /// Index of a beam by name.
    pub fn beam_index(&self, name: &str) -> Option<usize> {
        self.beams.iter().position(|b| b.name == name)
    }

    /// Component set (shared by all beams).
    pub fn components(&self) -> Components {
        self.components
    }

    /// Components per field.
    pub fn k(&self) -> usize {
        self.components.k()
    }

    /// Column offset of beam `b`'s vector in the global vector.
    pub fn offset(&self, b: usize) -> usize {
        self.offsets[b]
    }

    /// Length of the global vector (= number of rows of the step system).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Reference kinematics of every beam.
    pub fn reference(&self) -> &[Kinematics] {
        &self.reference
    }

    /// Joints and supports (joints first), resolved.
    pub fn joints(&self) -> &[JointInfo] {
        &self.joints
    }

    /// Index (into [`Structure::joints`]) of a joint or support by name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The joint definitions as given.
    pub fn joint_definitions(&self) -> (&[Joint], &[Support]) {
        (&self.joint_defs, &self.support_defs)
    }

    /// Free ends `(beam, end, first row)`: closed by `x2_end = 0`.
    pub fn free_ends(&self) -> &[(usize, End, usize)] {
        &self.free_ends
    }

    /// Number of constraint rows (`2k` per beam).
    pub fn n_constraint_rows(&self) -> usize {
        self.n_constraint_rows
    }

    /// Node index of a beam end.
    pub fn end_node(&self, b: usize, end: End) -> usize {
        end_node(&self.beams[b].beam, end)
    }

    /// Global column of component `a` of `x1` at the node of a beam end.
    pub fn x1_column(&self, b: usize, end: End, a: usize) -> usize {
        let beam = &self.beams[b].beam;
        self.offsets[b] + beam.x1_index(end_node(beam, end), a)
    }

    /// Global column of component `a` of the end value (`x2_L` or `x2_R`).
    pub fn x2_end_column(&self, b: usize, end: End, a: usize) -> usize {
        let beam = &self.beams[b].beam;
        self.offsets[b]
            + match end {
                End::Start => beam.left_index(a),
                End::End => beam.right_index(a),
            }
    }

    /// A beam's slice of a global vector.
    pub fn beam_slice<'a>(&self, b: usize, x: &'a [f64]) -> &'a [f64] {
        &x[self.offsets[b]..self.offsets[b] + self.beams[b].beam.dim()]
    }

    /// Label of every constraint row.
    pub fn row_labels(&self) -> Vec<RowLabel> {
        let mut out = vec![RowLabel { owner: String::new(), kind: None }; self.n_constraint_rows];
        for j in &self.joints {
            let owner = if j.ground {
                Owner::Support(j.name.clone())
            } else {
                Owner::Joint(j.name.clone())
            }
            .to_string();
            let identity = vec![Matrix3::identity(); j.ends.len()];
            for (i, r) in rows(&j.axes, &j.signs, j.ground, &identity).iter().enumerate() {
                out[j.first_row + i] = RowLabel { owner: owner.clone(), kind: Some(r.kind) };
            }
        }
        for &(b, e, r0) in &self.free_ends {
            for a in 0..self.k() {
                out[r0 + a] = RowLabel {
                    owner: format!("free {} of beam `{}`", e.name(), self.beams[b].name),
                    kind: None,
                };
            }
        }
        out
    }

    /// Coefficients of one joint's rows at the given end rotations: a dense
    /// `n_rows × (n_ends · 2k)` matrix on the slots `[x1 of end 0, x2 of end 0, x1 of end 1, …]`
    /// (row-major), the slots' global columns, and the right-hand side per row given the
    /// joint torques `tau` (one per active axis; only free angular axes may be non-zero).
    pub(crate) fn joint_coefficients(
        &self,
        j: &JointInfo,
        rotations: &[Matrix3<f64>],
        out: &mut [f64],
    ) {
        let k = self.k();
        let idx = self.components.indices();
        let n_slots = j.ends.len() * 2 * k;
        out.iter_mut().for_each(|v| *v = 0.0);
        for (r, row) in rows(&j.axes, &j.signs, j.ground, rotations).iter().enumerate() {
            for t in &row.terms {
                let base = t.end * 2 * k + if t.on_velocity { 0 } else { k };
                for a in 0..k {
                    let i = idx[a];
                    let c = match (t.part, i < 3) {
                        (Part::Linear, true) => t.direction[i],
                        (Part::Angular, false) => t.direction[i - 3],
                        _ => 0.0,
                    };
                    out[r * n_slots + base + a] += c;
                }
            }
        }
    }

    /// Global columns of a joint's slots (see `Structure::joint_coefficients`).
    pub fn joint_slots(&self, j: &JointInfo) -> Vec<usize> {
        let k = self.k();
        let mut out = Vec::with_capacity(j.ends.len() * 2 * k);
        for &(b, e) in &j.ends {
            out.extend((0..k).map(|a| self.x1_column(b, e, a)));
            out.extend((0..k).map(|a| self.x2_end_column(b, e, a)));
        }
        out
    }

    /// Right-hand sides of a joint's rows for joint torques `tau` (indexed by active axis):
    /// free rows `u_j·m_j = −σ_j τ_j`, with `τ_0 = −τ`, `τ_1 = +τ` for a two-end joint and
    /// `τ_0 = τ` for a support.
    pub(crate) fn joint_rhs(&self, j: &JointInfo, tau: &[f64], out: &mut [f64]) {
        let identity = vec![Matrix3::identity(); j.ends.len()];
        for (r, row) in rows(&j.axes, &j.signs, j.ground, &identity).iter().enumerate() {
            out[r] = 0.0;
            if row.kind == RowKind::Free && tau[row.axis] != 0.0 {
                let tj = if j.ground {
                    tau[row.axis]
                } else if row.end == 0 {
                    -tau[row.axis]
                } else {
                    tau[row.axis]
                };
                out[r] = -j.signs[row.end] * tj;
            }
        }
    }

    /// The linearised constraint matrix `G` at the reference configuration (theory.md §4):
    /// rows as [`Structure::row_labels`], columns the global vector; entries `(row, col, value)`
    /// without zeros. `G X = 0` states velocity compatibility, force balance, free directions
    /// and free ends with `T` frozen at the reference.
    pub fn constraint_matrix(&self) -> ConstraintMatrix {
        let k = self.k();
        let mut entries = Vec::new();
        for j in &self.joints {
            let rot: Vec<Matrix3<f64>> = j
                .ends
                .iter()
                .map(|&(b, e)| rotation(&self.reference[b].xi[self.end_node(b, e)]))
                .collect();
            let n_slots = j.ends.len() * 2 * k;
            let mut coef = vec![0.0; j.n_rows * n_slots];
            self.joint_coefficients(j, &rot, &mut coef);
            let slots = self.joint_slots(j);
            for r in 0..j.n_rows {
                for (s, &col) in slots.iter().enumerate() {
                    let v = coef[r * n_slots + s];
                    if v.abs() > 1e-15 {
                        entries.push((j.first_row + r, col, v));
                    }
                }
            }
        }
        for &(b, e, r0) in &self.free_ends {
            for a in 0..k {
                entries.push((r0 + a, self.x2_end_column(b, e, a), 1.0));
            }
        }
        ConstraintMatrix {
            rows: self.n_constraint_rows,
            cols: self.dim,
            entries,
            labels: self.row_labels(),
        }
    }

    /// Global linear operators `B`, `A` at rest (theory.md §4): each beam's
    /// [`intrinsic_beam::LinearOperators`] shifted to its offset; rows are indexed like
    /// the global vector (beam row `i` ↔ unknown `i`), so the end-value rows are empty and
    /// are supplied by [`Structure::constraint_matrix`]. Returns `(B, A, damping)` triplets.
    #[allow(clippy::type_complexity)]
    pub fn linear_operators(
        &self,
    ) -> (Vec<(usize, usize, f64)>, Vec<(usize, usize, f64)>, Vec<(usize, usize, f64)>) {
        let (mut b_out, mut a_out, mut d_out) = (Vec::new(), Vec::new(), Vec::new());
        for (bi, b) in self.beams.iter().enumerate() {
            let o = self.offsets[bi];
            let ops = b.beam.linear_operators();
            b_out.extend(ops.b.iter().map(|&(r, c, v)| (o + r, o + c, v)));
            a_out.extend(ops.a.iter().map(|&(r, c, v)| (o + r, o + c, v)));
            d_out.extend(ops.damping.iter().map(|&(r, c, v)| (o + r, o + c, v)));
        }
        (b_out, a_out, d_out)
    }

    /// A global state of rigid-body motion with angular velocity `omega` (global) about the
    /// point `center`, in the reference configuration: at every node `ω = Tᵀ Ω`,
    /// `v = Tᵀ (Ω × (r − center))`; forces zero. This is the paper's disturbance (§5.2).
    pub fn rigid_rotation_state(&self, omega: Vector3<f64>, center: Vector3<f64>) -> Vec<f64> {
        let mut x = vec![0.0; self.dim];
        for (bi, b) in self.beams.iter().enumerate() {
            let o = self.offsets[bi];
            let kin = &self.reference[bi];
            for n in 0..b.beam.n_nodes() {
                let t = rotation(&kin.xi[n]);
                let v = t.transpose() * omega.cross(&(kin.r[n] - center));
                let w = t.transpose() * omega;
                let full = join(&v, &w);
                b.beam.set_x1(&mut x[o..o + b.beam.dim()], n, &full);
            }
        }
        x
    }

    /// Rigid rotation of the structure about `axis` through `center` by `angle`: a new
    /// structure whose explicit placements are turned (attached ones follow). Joint axes given
    /// in the global frame are turned too.
    pub fn rotated(&self, axis: Vector3<f64>, angle: f64, center: Vector3<f64>) -> Result<Self> {
        let q = axis_angle(&axis, angle);
        let rmat = rotation(&q);
        let beams = self
            .beams
            .iter()
            .map(|b| {
                let placement = match &b.placement {
                    Placement::At { origin, quaternion } => Placement::At {
                        origin: center + rmat * (origin - center),
                        quaternion: quat_mul(&q, &(quaternion / quaternion.norm())),
                    },
                    other => other.clone(),
                };
                StructureBeam { name: b.name.clone(), beam: b.beam.clone(), placement }
            })
            .collect();
        let turn = |kind: &JointKind| match kind {
            JointKind::Hinge { axis: a, frame: crate::joint::Frame::Global } => {
                let v = rmat * Vector3::from(*a);
                JointKind::Hinge { axis: [v.x, v.y, v.z], frame: crate::joint::Frame::Global }
            }
            other => other.clone(),
        };
        let joints =
            self.joint_defs.iter().map(|j| Joint { kind: turn(&j.kind), ..j.clone() }).collect();
        let supports = self
            .support_defs
            .iter()
            .map(|s| Support { kind: turn(&s.kind), ..s.clone() })
            .collect();
        Structure::new(
            beams,
            joints,
            supports,
            StructureSettings { allow_disconnected: true, ..Default::default() },
        )
    }

    /// Total mass per unit length times `g` as a dead distributed load value for beam `b`
    /// (`[m g, 0]` with `m = M11`); an error if the section's translational mass block is not
    /// `m I` or couples to rotations (offset centre of mass is not supported by gravity here).
    pub fn gravity_load(&self, b: usize, g: &Vector3<f64>) -> Result<Vector6<f64>> {
        let m = &self.beams[b].beam.section().mass;
        let m0 = m[(0, 0)];
        let mut ok = true;
        for i in 0..3 {
            for j in 0..6 {
                let expect = if i == j { m0 } else { 0.0 };
                if (m[(i, j)] - expect).abs() > 1e-12 * m0.abs().max(1e-300) {
                    ok = false;
                }
            }
        }
        if !ok {
            return Err(MultibodyError::BadInput {
                input: format!("gravity on beam `{}`", self.beams[b].name),
                reason: "the section's translational mass block must be m·I without coupling to rotations".into(),
            });
        }
        Ok(join(&(g * m0), &Vector3::zeros()))
    }

    /// Mass per unit length `M11` of beam `b`.
    pub fn mass_per_length(&self, b: usize) -> f64 {
        self.beams[b].beam.section().mass[(0, 0)]
    }

    /// Splits a global `x2_end` value (6-vector) of beam `b` end `e` from a global vector.
    pub fn end_value(&self, x: &[f64], b: usize, e: End) -> Vector6<f64> {
        let beam = &self.beams[b].beam;
        let s = self.beam_slice(b, x);
        match e {
            End::Start => beam.x2_left(s),
            End::End => beam.x2_right(s),
        }
    }

    /// `x1` (6-vector) at a beam end node of a global vector.
    pub fn end_velocity(&self, x: &[f64], b: usize, e: End) -> Vector6<f64> {
        let beam = &self.beams[b].beam;
        beam.x1(self.beam_slice(b, x), end_node(beam, e))
    }
}

/// Load `−σ T y` that an end value `y = x2_end` (local) applies on its beam, in global
/// components (`[force, moment]`).
pub fn end_load_global(t: &Matrix3<f64>, sign: f64, y: &Vector6<f64>) -> Vector6<f64> {
    let (f, m) = halves(y);
    join(&(t * f * -sign), &(t * m * -sign))
}

/// The linearised constraint rows `G` (see [`Structure::constraint_matrix`]).
#[derive(Clone, Debug)]
pub struct ConstraintMatrix {
    /// Number of rows.
    pub rows: usize,
    /// Number of columns (global vector length).
    pub cols: usize,
    /// Non-zero entries `(row, col, value)`.
    pub entries: Vec<(usize, usize, f64)>,
    /// What each row states.
    pub labels: Vec<RowLabel>,
}

impl ConstraintMatrix {
    /// `G` as a dense faer matrix.
    pub fn to_dense(&self) -> faer::Mat<f64> {
        let mut g = faer::Mat::zeros(self.rows, self.cols);
        for &(r, c, v) in &self.entries {
            g[(r, c)] += v;
        }
        g
    }
}
