//! Modes of a `multibody_constraints::Structure`: layout, operators, damping, rigid-mode
//! candidates and joint-torque inputs taken from the beam and multibody crates.

use crate::basis::{BasisSettings, ModalBasis};
use crate::eigen::SecondOrderProblem;
use crate::error::{invalid, Result};
use crate::layout::{BeamLayout, Components, FullIndex, Layout};
use crate::rigid::{rigid_rotation_fields, RigidRotation};
use crate::rom::Input;
use faer::Mat;
use intrinsic_beam::rotation::rotation;
use multibody_constraints::{Placement, Structure};
use nalgebra::{Matrix3, Vector3};

/// Everything the modal route needs from a structure at its reference configuration.
#[derive(Clone, Debug)]
pub struct StructureModel {
    /// Beam layout and reference configuration.
    pub layout: Layout,
    /// `B1`, `B2`, `D`, `G1` of the linearised structure.
    pub problem: SecondOrderProblem,
    /// FE damping operator on `X1` (n1 × n1).
    pub damping: Mat<f64>,
    /// Rigid rotations fixing the rigid-mode basis (theory.md §4), as `X1` fields.
    pub rigid_candidates: Mat<f64>,
}

/// Beams reachable from `start` through joints other than `skip` (ground supports excluded).
fn reachable(structure: &Structure, start: &[usize], skip: Option<usize>) -> Vec<usize> {
    let nb = structure.beams().len();
    let mut seen = vec![false; nb];
    let mut stack: Vec<usize> = start.to_vec();
    while let Some(b) = stack.pop() {
        if seen[b] {
            continue;
        }
        seen[b] = true;
        for (ji, j) in structure.joints().iter().enumerate() {
            if j.ground || Some(ji) == skip || !j.ends.iter().any(|e| e.0 == b) {
                continue;
            }
            stack.extend(j.ends.iter().map(|e| e.0).filter(|&x| !seen[x]));
        }
    }
    (0..nb).filter(|&b| seen[b]).collect()
}

/// Beam layout and reference configuration of `structure`.
pub(crate) fn layout_of(structure: &Structure) -> Result<Layout> {
    let components: Components = structure.components();
    let mut beams = Vec::new();
    for (b, sb) in structure.beams().iter().enumerate() {
        let kin = &structure.reference()[b];
        let start_from = match &sb.placement {
            Placement::Attached { joint, .. } => {
                let ji = structure.joint_index(joint).ok_or_else(|| {
                    invalid(format!("beam `{}` placement joint", sb.name), joint, "unknown joint")
                })?;
                let (b0, e0) = structure.joints()[ji].ends[0];
                Some((b0, structure.end_node(b0, e0)))
            }
            _ => None,
        };
        beams.push(BeamLayout {
            name: sb.name.clone(),
            element_lengths: sb.beam.mesh().lengths().to_vec(),
            reference_quaternions: kin.xi.iter().map(|q| [q[0], q[1], q[2], q[3]]).collect(),
            reference_positions: kin.r.iter().map(|r| [r.x, r.y, r.z]).collect(),
            start_from,
        });
    }
    Layout::new(components, beams)
}

/// The rigid rotations fixing the rigid-mode basis (theory.md §4) as `X1` fields (n1 × count):
/// about the free axes of the supports first, then joint by joint by distance from the ground.
pub(crate) fn rigid_candidates_of(structure: &Structure, layout: &Layout) -> Result<Mat<f64>> {
    // Rigid candidates: supports first, then joints by distance from the ground.
    let joints = structure.joints();
    let grounded: Vec<usize> = joints.iter().filter(|j| j.ground).map(|j| j.ends[0].0).collect();
    let depth = |b: usize| -> usize {
        let mut d = 0;
        let mut frontier = grounded.clone();
        let mut seen = vec![false; structure.beams().len()];
        while !frontier.is_empty() {
            if frontier.contains(&b) {
                return d;
            }
            frontier.iter().for_each(|&x| seen[x] = true);
            let mut next = Vec::new();
            for &x in &frontier {
                for j in joints.iter().filter(|j| !j.ground && j.ends.iter().any(|e| e.0 == x)) {
                    next.extend(j.ends.iter().map(|e| e.0).filter(|&y| !seen[y]));
                }
            }
            next.sort_unstable();
            next.dedup();
            frontier = next;
            d += 1;
        }
        usize::MAX
    };
    let mut order: Vec<usize> = (0..joints.len()).collect();
    order.sort_by_key(|&ji| (!joints[ji].ground, depth(joints[ji].ends[0].0), ji));
    let mut rotations = Vec::new();
    for ji in order {
        let j = &joints[ji];
        let rots: Vec<Matrix3<f64>> = j
            .ends
            .iter()
            .map(|&(b, e)| rotation(&structure.reference()[b].xi[structure.end_node(b, e)]))
            .collect();
        let (b0, e0) = j.ends[0];
        let pivot = structure.reference()[b0].r[structure.end_node(b0, e0)];
        let beams = if j.ground {
            reachable(structure, &[b0], None)
        } else {
            reachable(structure, &j.ends[1..].iter().map(|e| e.0).collect::<Vec<_>>(), Some(ji))
        };
        for axis in j.free_rotation_axes().into_iter().map(|i| &j.axes[i]) {
            let global: Vector3<f64> = rots[0] * axis.local_at(0, &rots);
            rotations.push(RigidRotation {
                pivot: [pivot.x, pivot.y, pivot.z],
                axis: [global.x, global.y, global.z],
                beams: beams.clone(),
            });
        }
    }
    rigid_rotation_fields(layout, &rotations)
}

impl StructureModel {
    /// Extracts layout, operators, damping and rigid candidates from `structure`.
    pub fn new(structure: &Structure) -> Result<Self> {
        let layout = layout_of(structure)?;
        let (b, a, d) = structure.linear_operators();
        let g = structure.constraint_matrix();
        let problem = SecondOrderProblem::from_full_entries(
            &layout,
            b,
            a,
            g.rows,
            g.entries.iter().copied(),
        )?;
        let n1 = layout.n1();
        let mut damping = Mat::<f64>::zeros(n1, n1);
        for (i, j, v) in d {
            if let (FullIndex::X1(p), FullIndex::X1(q)) =
                (layout.classify_full(i), layout.classify_full(j))
            {
                damping[(p, q)] += v;
            }
        }
        let rigid_candidates = rigid_candidates_of(structure, &layout)?;
        Ok(StructureModel { layout, problem, damping, rigid_candidates })
    }

    /// The constrained modes of the structure (rigid basis fixed by the joint rotations).
    pub fn modes(&self, settings: &BasisSettings) -> Result<ModalBasis> {
        ModalBasis::compute(
            self.layout.clone(),
            &self.problem,
            settings,
            Some(self.rigid_candidates.as_ref()),
        )
    }

    /// A joint-torque input about free rotation axis `axis` of joint/support `joint` (`None`:
    /// its only free rotation axis), with the plant's sign: `+τ` on the second end, `−τ` on
    /// the first; a support's torque acts `+τ` on its end. Applied as follower point moments
    /// at the end nodes, `[B_u]_i = φ1i(end)ᵀ (±u_local)`.
    pub fn joint_torque(
        &self,
        structure: &Structure,
        name: &str,
        joint: &str,
        axis: Option<usize>,
    ) -> Result<Input> {
        let ji = structure.joint_index(joint).ok_or_else(|| {
            invalid(format!("input `{name}`: joint"), joint, "unknown joint or support")
        })?;
        let j = &structure.joints()[ji];
        let a = j.free_rotation_axis(axis)?;
        if !j.ground && j.ends.len() != 2 {
            return Err(invalid(
                format!("input `{name}`: joint"),
                joint,
                "torques need a two-end joint or a support",
            ));
        }
        let rots: Vec<Matrix3<f64>> = j
            .ends
            .iter()
            .map(|&(b, e)| rotation(&structure.reference()[b].xi[structure.end_node(b, e)]))
            .collect();
        let comps = self.layout.components;
        let mut entries = Vec::new();
        for (je, &(b, e)) in j.ends.iter().enumerate() {
            let sign = if j.ground || je == 1 { 1.0 } else { -1.0 };
            let u = j.axes[a].local_at(je, &rots);
            let node = structure.end_node(b, e);
            for i in 0..3 {
                if u[i] == 0.0 {
                    continue;
                }
                match comps.active_index(3 + i) {
                    Some(c) => entries.push((self.layout.x1_index(b, node, c), sign * u[i])),
                    None if u[i].abs() < 1e-12 => {}
                    None => {
                        return Err(invalid(
                            format!("input `{name}`: axis"),
                            a,
                            "out-of-plane torque in a planar structure",
                        ))
                    }
                }
            }
        }
        Ok(Input { name: name.to_string(), entries })
    }
}
