//! Unit tests of the eigen route and the modal basis on small assembled operators.

use crate::basis::{BasisSettings, KindCounts, ModalBasis, ModeKind, ModeSelection};
use crate::layout::{BeamLayout, Components, Layout};
use crate::rigid::{chain_rotations, rigid_rotation_fields};
use crate::testing::*;
use std::f64::consts::PI;

fn single(components: Components, n: usize, fixed: &[usize]) -> ModalBasis {
    let layout = Layout::new(
        components,
        vec![BeamLayout::straight("a", 1.0, n, [0.0; 3], [1.0, 0.0, 0.0, 0.0])],
    )
    .unwrap();
    let rows = fix_rows(&layout, 0, 0, fixed);
    let p = problem(&layout, &paper_2d(), rows);
    ModalBasis::compute(layout, &p, &BasisSettings::default(), None).unwrap()
}

#[test]
fn free_free_axial_and_rigid_count() {
    let basis = single(Components::Planar, 40, &[]);
    assert_eq!(basis.n_rigid(), 3, "a free planar beam has 3 rigid modes");
    let axial: Vec<f64> = (0..basis.n_modes())
        .filter(|&j| basis.kinds()[j] == ModeKind::Axial)
        .map(|j| basis.omega()[j])
        .collect();
    let c = 1000f64.sqrt();
    for (kk, w) in axial.iter().take(3).enumerate() {
        let exact = (kk + 1) as f64 * PI * c;
        // second-order scheme, h = 1/40: relative error ≈ (kπh)²/24 < 3e-3 for k ≤ 3
        assert!((w / exact - 1.0).abs() < 3e-3, "axial {kk}: {w} vs {exact}");
    }
}

/// Bending frequencies (lowest three) of a single beam at `n` elements.
fn bending(n: usize, fixed: &[usize]) -> Vec<f64> {
    let b = single(Components::Planar, n, fixed);
    (0..b.n_modes())
        .filter(|&j| b.kinds()[j] == ModeKind::BendingE2)
        .map(|j| b.omega()[j])
        .take(3)
        .collect()
}

#[test]
fn single_beam_bending_converges_at_second_order() {
    // Euler–Bernoulli with EI = m = L = 1: pinned–free tan βL = tanh βL, free–free
    // cos βL cosh βL = 1; ω = (βL)². Shear (GA = 1e5) and rotary inertia (1e-5) shift the
    // continuum values by ≈ ½(βL)²·2e-5 ≤ 6e-4 relative for these modes.
    let cases: [(&[usize], [f64; 2]); 2] = [
        (&[0, 1], [3.926_602_312_047_919, 7.068_582_745_628_732]),
        (&[], [4.730_040_744_862_704, 7.853_204_624_095_838]),
    ];
    for (fixed, beta) in cases {
        let w: Vec<Vec<f64>> = [20, 40, 80].iter().map(|&n| bending(n, fixed)).collect();
        for mode in 0..2 {
            let order = ((w[0][mode] - w[1][mode]) / (w[1][mode] - w[2][mode])).log2();
            assert!(order > 1.9 && order < 2.1, "order {order} (fixed {fixed:?}, mode {mode})");
            let exact = beta[mode] * beta[mode];
            assert!((w[2][mode] / exact - 1.0).abs() < 1.5e-3, "{} vs {exact}", w[2][mode]);
        }
    }
}

#[test]
fn two_link_2d_modes_orthonormal_and_labelled() {
    let (layout, p) = two_link_2d(50, 0.0);
    let cand = rigid_rotation_fields(
        &layout,
        &chain_rotations(&layout, &[vec![[0.0, 1.0, 0.0]], vec![[0.0, 1.0, 0.0]]]).unwrap(),
    )
    .unwrap();
    let basis =
        ModalBasis::compute(layout, &p, &BasisSettings::default(), Some(cand.as_ref())).unwrap();
    assert_eq!(basis.n_rigid(), 2);
    let (e1, e2, e3) = basis.select(&ModeSelection::Lowest(40)).unwrap().orthonormality_residuals();
    assert!(e1 < 1e-12, "M-orthonormality {e1}");
    // φ2 from orthonormal left singular vectors (SVD route): round-off, not cond(K)
    assert!(e2 < 1e-12, "C-orthonormality {e2}");
    assert!(e3 < 1e-12 * basis.omega()[39], "duality {e3}");
    let labels = basis.labels();
    let first5: Vec<&str> = labels[2..7].iter().map(|s| s.as_str()).collect();
    assert_eq!(first5.iter().filter(|l| **l == "bending").count(), 4, "{first5:?}");
    assert_eq!(first5.iter().filter(|l| **l == "axial").count(), 1, "{first5:?}");
    // axial modes (2k−1)π/4 √(EA/m)
    let axial: Vec<f64> =
        (0..basis.n_modes()).filter(|&j| labels[j] == "axial").map(|j| basis.omega()[j]).collect();
    for kk in 0..3 {
        let exact = (2 * kk + 1) as f64 * PI / 4.0 * 1000f64.sqrt();
        assert!((axial[kk] / exact - 1.0).abs() < 2e-3, "{} vs {exact}", axial[kk]);
    }
    let sel = basis.select(&ModeSelection::ByKind(KindCounts::paper_2d())).unwrap();
    assert_eq!(sel.n_modes(), 10);
    assert_eq!(sel.n_rigid(), 2);
    assert!(sel.omega().iter().all(|w| *w >= 0.0));
    assert!(basis.lambda().iter().all(|l| *l >= -1e-12 * basis.lambda_max()));
}

#[test]
fn two_link_3d_rigid_count_and_kinds() {
    let (layout, p) = two_link_3d(10, 0.0);
    let basis = ModalBasis::compute(layout, &p, &BasisSettings::default(), None).unwrap();
    assert_eq!(basis.n_rigid(), 4);
    let sel = basis.select(&ModeSelection::ByKind(KindCounts::paper_3d())).unwrap();
    assert_eq!(sel.n_modes(), 20);
    let (e1, _, _) = sel.orthonormality_residuals();
    assert!(e1 < 1e-12);
}

#[test]
fn planar_equals_spatial_with_rigid_out_of_plane() {
    let (_, p2) = two_link_2d(12, 0.3);
    let layout = two_link_layout(Components::Planar, 12, 0.3);
    let b2 = ModalBasis::compute(layout, &p2, &BasisSettings::default(), None).unwrap();
    // spatial, paper 2D section with C = 0 out of plane and massless ω1, ω3
    let l3 = two_link_layout(Components::Spatial, 12, 0.3);
    let mut rows = fix_rows(&l3, 0, 0, &[0, 1, 2, 3, 5]);
    rows.extend(joint_rows(&l3, 0, 1, &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], false));
    rows.extend(joint_rows(&l3, 0, 1, &[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], true));
    let p3 = problem(&l3, &paper_2d(), rows);
    let b3 = ModalBasis::compute(l3, &p3, &BasisSettings::default(), None).unwrap();
    assert_eq!(b3.n_rigid(), b2.n_rigid());
    for j in 0..10 {
        let (a, b) = (b2.omega()[j], b3.omega()[j]);
        assert!((a - b).abs() <= 1e-8 * b.max(1.0), "mode {j}: planar {a} spatial {b}");
    }
}
