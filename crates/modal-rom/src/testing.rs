//! Test-only assembly of small staggered operators (theory.md §2) for early eigen tests.
//!
//! Mirrors the scheme of theory.md §2 with the beam crate's pointwise `E`; the verification
//! cases use the beam and multibody crates' own assembly.

use crate::eigen::SecondOrderProblem;
use crate::layout::{BeamLayout, Components, Layout};
use faer::Mat;
use intrinsic_beam::operators::e_matrix;
use intrinsic_beam::rotation::rotation;
use nalgebra::{Vector3, Vector4};

/// Section data (spatial diagonals).
pub struct Section {
    pub m: [f64; 6],
    pub c: [f64; 6],
}

/// Quaternion of a rotation by `angle` about global e2.
pub fn quat_e2(angle: f64) -> [f64; 4] {
    [(angle / 2.0).cos(), 0.0, (angle / 2.0).sin(), 0.0]
}

/// Assembles B1, B2, D for the layout (uniform section, straight beams).
pub fn operators(layout: &Layout, s: &Section) -> (Mat<f64>, Mat<f64>, Mat<f64>) {
    let comps = layout.components;
    let k = comps.k();
    let (n1, n2) = (layout.n1(), layout.n2());
    let mut b1 = Mat::zeros(n1, n1);
    let mut b2 = Mat::zeros(n2, n2);
    let mut d = Mat::zeros(n1, n2);
    let e = e_matrix(&Vector3::zeros());
    for (b, beam) in layout.beams.iter().enumerate() {
        for n in 0..beam.n_nodes() {
            for c in 0..k {
                let i = layout.x1_index(b, n, c);
                b1[(i, i)] = beam.node_weight(n) * s.m[comps.spatial_index(c)];
            }
        }
        for el in 0..beam.n_elements() {
            let h = beam.element_lengths[el];
            for r in 0..k {
                let i = layout.x2_index(b, el, r);
                b2[(i, i)] = h * s.c[comps.spatial_index(r)];
                // node el gets +x2_el, node el+1 gets −x2_el; both get h/2 E x2_el
                for c in 0..k {
                    let ev = e[(comps.spatial_index(r), comps.spatial_index(c))] * h / 2.0;
                    let col = layout.x2_index(b, el, c);
                    d[(layout.x1_index(b, el, r), col)] += ev + if r == c { 1.0 } else { 0.0 };
                    d[(layout.x1_index(b, el + 1, r), col)] += ev - if r == c { 1.0 } else { 0.0 };
                }
            }
        }
    }
    (b1, b2, d)
}

/// Velocity rows fixing active components `comps_fixed` of node `n` of beam `b`.
pub fn fix_rows(
    layout: &Layout,
    b: usize,
    n: usize,
    comps_fixed: &[usize],
) -> Vec<Vec<(usize, f64)>> {
    comps_fixed.iter().map(|&c| vec![(layout.x1_index(b, n, c), 1.0)]).collect()
}

/// Rows `dᵀ T_a x_a(end) − dᵀ T_b x_b(0) = 0` for global directions `dirs` (translational if
/// `angular == false`), joining the end of beam `a` to the start of beam `b`.
pub fn joint_rows(
    layout: &Layout,
    a: usize,
    b: usize,
    dirs: &[[f64; 3]],
    angular: bool,
) -> Vec<Vec<(usize, f64)>> {
    let comps = layout.components;
    let na = layout.beams[a].n_nodes() - 1;
    let ta = rotation(&Vector4::from_column_slice(&layout.beams[a].reference_quaternions[na]));
    let tb = rotation(&Vector4::from_column_slice(&layout.beams[b].reference_quaternions[0]));
    let off = if angular { 3 } else { 0 };
    dirs.iter()
        .map(|dir| {
            let d = Vector3::from_column_slice(dir);
            let (ua, ub) = (ta.transpose() * d, tb.transpose() * d);
            let mut row = Vec::new();
            for i in 0..3 {
                if let Some(c) = comps.active_index(off + i) {
                    row.push((layout.x1_index(a, na, c), ua[i]));
                    row.push((layout.x1_index(b, 0, c), -ub[i]));
                }
            }
            row
        })
        .collect()
}

/// Builds the problem from rows.
pub fn problem(layout: &Layout, s: &Section, rows: Vec<Vec<(usize, f64)>>) -> SecondOrderProblem {
    let (b1, b2, d) = operators(layout, s);
    let mut g = Mat::zeros(rows.len(), layout.n1());
    for (r, row) in rows.iter().enumerate() {
        for &(i, v) in row {
            if v.abs() > 1e-15 {
                g[(r, i)] += v;
            }
        }
    }
    SecondOrderProblem::new(b1, b2, d, g).unwrap()
}

/// Paper 2D section (theory.md §9), spatial diagonals with `∞` stiffness as `C = 0`.
pub fn paper_2d() -> Section {
    Section { m: [1.0, 1.0, 1.0, 0.0, 1e-5, 0.0], c: [1e-3, 0.0, 1e-5, 0.0, 1.0, 0.0] }
}

/// Paper 3D section.
pub fn paper_3d() -> Section {
    Section { m: [1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4], c: [1e-3, 1e-5, 1e-5, 20.0, 1.0, 0.5] }
}

/// Two links of length 1 at joint angle `angle` (about e2), `n` elements each.
pub fn two_link_layout(components: Components, n: usize, angle: f64) -> Layout {
    let a = BeamLayout::straight("a", 1.0, n, [0.0; 3], [1.0, 0.0, 0.0, 0.0]);
    // rotation about e2 by −angle turns e1 towards +e3
    let mut b = BeamLayout::straight("b", 1.0, n, [1.0, 0.0, 0.0], quat_e2(-angle));
    b.start_from = Some((0, n));
    Layout::new(components, vec![a, b]).unwrap()
}

/// The paper's 2D two-link (planar, hinges about e2) at `angle`.
pub fn two_link_2d(n: usize, angle: f64) -> (Layout, SecondOrderProblem) {
    let layout = two_link_layout(Components::Planar, n, angle);
    let mut rows = fix_rows(&layout, 0, 0, &[0, 1]);
    rows.extend(joint_rows(&layout, 0, 1, &[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], false));
    let p = problem(&layout, &paper_2d(), rows);
    (layout, p)
}

/// The paper's 3D two-link (universal joints) at `angle`.
pub fn two_link_3d(n: usize, angle: f64) -> (Layout, SecondOrderProblem) {
    let layout = two_link_layout(Components::Spatial, n, angle);
    let mut rows = fix_rows(&layout, 0, 0, &[0, 1, 2, 3]);
    rows.extend(joint_rows(
        &layout,
        0,
        1,
        &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        false,
    ));
    // torsion rigid in each end's own axis: ω1^a(L) = ω1^b(0)
    let na = layout.beams[0].n_nodes() - 1;
    rows.push(vec![(layout.x1_index(0, na, 3), 1.0), (layout.x1_index(1, 0, 3), -1.0)]);
    let p = problem(&layout, &paper_3d(), rows);
    (layout, p)
}
