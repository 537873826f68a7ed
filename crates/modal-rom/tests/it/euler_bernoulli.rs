//! Euler–Bernoulli sections (rigid shear and massless rotation) through the constrained route.
//!
//! The defect these tests guard against: from 50 elements on, the low bending modes of the
//! Euler–Bernoulli cantilever were classified as rigid, because the rigid test was relative to
//! `max ω²`, which grows like `N⁶` for this section (node rotations slaved to deflections by
//! the trapezoidal shear rows), and free ends left an undetected massless direction with a
//! spurious `ω² ≈ 1e20`. These tests hold the route to the closed form, to its order, and to
//! the exact scaling of the discrete model (the cross-check against an independent dense
//! single-beam route is in the verification crate, `tests/tests/it/dense_modes.rs`).

use intrinsic_beam::closed_form::{bending, Supports};
use intrinsic_beam::{samples, Beam, Components, Mesh, Section};
use modal_rom::{BasisSettings, ModalBasis, ModeKind, StructureModel};
use multibody_constraints::{End, EndRef, JointKind, Support};
use multibody_constraints::{Placement, Structure, StructureBeam, StructureSettings};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

/// A single straight beam along e1 with the given support at `s = 0` (`None`: free–free).
fn structure(
    section: Section,
    length: f64,
    n: usize,
    components: Components,
    support: Option<JointKind>,
) -> Structure {
    let beam = Beam::new(section, Mesh::uniform(length, n).unwrap(), components).unwrap();
    let supports = support
        .map(|kind| {
            vec![Support { name: "root".into(), end: EndRef::new("beam", End::Start), kind }]
        })
        .unwrap_or_default();
    Structure::new(
        vec![StructureBeam::new("beam", beam, Placement::origin())],
        vec![],
        supports,
        StructureSettings::default(),
    )
    .unwrap()
}

fn modes(s: &Structure) -> ModalBasis {
    StructureModel::new(s).unwrap().modes(&BasisSettings::default()).unwrap()
}

fn of_kind(b: &ModalBasis, kind: ModeKind) -> Vec<f64> {
    (0..b.n_modes()).filter(|&j| b.kinds()[j] == kind).map(|j| b.omega()[j]).collect()
}

/// Round-off bound of the SVD route for the lowest modes: `ε ω_max / ω` with
/// `ω_max ≈ 4.8 N³` (the slaved-rotation modes, `max ω² ≈ 23 N⁶` measured) and `ω ≥ 3.5`:
/// `≈ 1.3e-9` at 200 elements; 1e-8 leaves a margin of ~8.
const ROUND_OFF: f64 = 1e-8;

#[test]
fn cantilever_converges_to_the_closed_form_at_second_order() {
    let meshes = [10usize, 20, 50, 100, 200];
    let exact = bending(Supports::ClampedFree, 1.0, 1.0, 1.0, 3);
    // e[k][i]: relative error of bending mode k at meshes[i]
    let mut e = vec![Vec::new(); 3];
    for &n in &meshes {
        let b = modes(&structure(
            samples::euler_bernoulli_section(),
            1.0,
            n,
            Components::Planar,
            Some(JointKind::Weld),
        ));
        assert_eq!(b.n_rigid(), 0, "a clamped beam has no rigid mode ({n} elements)");
        // the first elastic mode is the first bending mode (the axial one is at 15.7 rad/s)
        assert_eq!(b.kinds()[0], ModeKind::BendingE2, "{n} elements: {:?}", &b.labels()[..3]);
        let w = of_kind(&b, ModeKind::BendingE2);
        for k in 0..3 {
            e[k].push(w[k] / exact[k] - 1.0);
        }
    }
    // Second order: e ≈ C h² with C measured at 200 elements: C1 = −0.26518, C2 = −0.24284,
    // C3 = +0.6048 (N²e of mode 1: −0.26527 at 10 elements). The h⁴ term moves N²e of mode 1
    // by 3.4e-4 at 10 elements; of modes 2 and 3 (βh 2.5 and 4.2 times larger) by 1.9e-3 and
    // 6.4e-3 at 50, so those are checked from 50 elements on (orders from 20 / 50).
    let c: Vec<f64> = (0..3).map(|k| e[k][4] * 200.0 * 200.0).collect();
    assert!(c[0] < -0.26 && c[0] > -0.27, "C1 = {}", c[0]);
    for (k, first, tol) in [(0usize, 0usize, 1e-3), (1, 2, 5e-3), (2, 2, 1e-2)] {
        for i in first..meshes.len() {
            let n = meshes[i] as f64;
            let ratio = e[k][i] * n * n / c[k];
            assert!((ratio - 1.0).abs() < tol, "mode {k}, {n} elements: N²e/C = {ratio}");
        }
    }
    for (k, first) in [(0usize, 0usize), (1, 1), (2, 2)] {
        for i in first..meshes.len() - 1 {
            let order =
                (e[k][i] / e[k][i + 1]).ln() / (meshes[i + 1] as f64 / meshes[i] as f64).ln();
            assert!((order - 2.0).abs() < 0.02, "mode {k}: order {order} at {}", meshes[i]);
        }
    }
}

/// Supports × components × meshes: rigid count, the closed form at second order, planar =
/// spatial, and the two bending families in the ratio `√(EI3/EI2) = √2`.
#[test]
fn supports_and_components_of_the_massless_rigid_section() {
    let cases = [
        (Some(JointKind::Weld), Supports::ClampedFree, [0usize, 0]),
        (Some(JointKind::Ball), Supports::PinnedFree, [1, 3]),
        (None, Supports::FreeFree, [3, 6]),
    ];
    for (support, closed, rigid) in cases {
        let exact = bending(closed, 1.0, 1.0, 1.0, 2);
        let meshes = [12usize, 45, 64, 130];
        // q[k][i] = e N² (relative error of bending mode k at meshes[i] times N²)
        let mut q = vec![Vec::new(); 2];
        for &n in &meshes {
            let mk = |c| structure(samples::euler_bernoulli_section(), 1.0, n, c, support.clone());
            let (planar, spatial) =
                (modes(&mk(Components::Planar)), modes(&mk(Components::Spatial)));
            assert_eq!(planar.n_rigid(), rigid[0], "{closed:?} planar, {n} elements");
            assert_eq!(spatial.n_rigid(), rigid[1], "{closed:?} spatial, {n} elements");
            // Mode count: v1, v3 at the unsupported nodes and ω2 at every free one, less one
            // shear row per element, less the alternating massless rotation when an end's
            // rotation is free (condensed): 2N (clamped), 2N (pinned), 2N + 2 (free–free). A
            // missed massless direction adds a spurious mode with ω ≈ 1e10 (the former route
            // at 20, 50, 200 elements); slaved-rotation modes stay below ≈ 4.8 N³ (measured).
            let dim = 2 * n + if closed == Supports::FreeFree { 2 } else { 0 };
            assert_eq!(planar.n_modes(), dim, "{closed:?} planar, {n} elements");
            let top = planar.omega().iter().fold(0.0f64, |a, &w| a.max(w));
            assert!(top < 10.0 * (n * n * n) as f64, "{closed:?} {n}: ω_max = {top:e}");
            let wp = of_kind(&planar, ModeKind::BendingE2);
            let ws = of_kind(&spatial, ModeKind::BendingE2);
            let w3 = of_kind(&spatial, ModeKind::BendingE3);
            for k in 0..2 {
                let (rs, r3) = (ws[k] / wp[k] - 1.0, w3[k] / (wp[k] * 2f64.sqrt()) - 1.0);
                assert!(rs.abs() < ROUND_OFF, "{closed:?} {n}: spatial/planar − 1 = {rs:e}");
                assert!(r3.abs() < ROUND_OFF, "{closed:?} {n}: e3/(√2 e2) − 1 = {r3:e}");
                let e = wp[k] / exact[k] - 1.0;
                // measured |e| / (βh)² ≤ 0.1155 (free–free mode 1), ω = β²
                assert!(e.abs() < 0.12 * exact[k] / (n * n) as f64, "{closed:?} {n} {k}: {e:e}");
                q[k].push(e * (n * n) as f64);
            }
        }
        // second order: N²e settles (measured deviation from the 130-element value ≤ 8.1 %
        // at 12 elements, pinned–free mode 2, and ≤ 2.4e-3 from 45 on)
        for k in 0..2 {
            for i in 0..meshes.len() - 1 {
                let dev = q[k][i] / q[k][meshes.len() - 1] - 1.0;
                let tol = if meshes[i] < 40 { 0.1 } else { 5e-3 };
                assert!(
                    dev.abs() < tol,
                    "{closed:?} mode {k} at {}: N²e off by {dev:e}",
                    meshes[i]
                );
            }
        }
    }
}

fn cfg() -> Config {
    Config { cases: 64, rng_seed: RngSeed::Fixed(20_261_121), ..Config::default() }
}

proptest! {
    #![proptest_config(cfg())]

    /// The discrete bending spectrum of a uniform mesh scales exactly as the continuum,
    /// `ω = Ω_N √(EI/(m L⁴))`: whatever EI, m, L (and axial stiffness), `ω L² √(m/EI)` equals
    /// the unit beam's to round-off, and no bending mode turns rigid.
    #[test]
    fn bending_spectrum_scales_exactly(
        n in 8usize..120,
        ei in 0.05f64..20.0,
        m in 0.05f64..20.0,
        length in 0.3f64..5.0,
        ea_over_ei in 10.0f64..1e6,
        clamped in any::<bool>(),
    ) {
        let support = if clamped { Some(JointKind::Weld) } else { None };
        let section = Section::from_diagonals(
            [m, m, m, 0.01 * m, 0.0, 0.0],
            [ea_over_ei * ei, f64::INFINITY, f64::INFINITY, 0.5 * ei, ei, 2.0 * ei],
        )
        .unwrap();
        let b = modes(&structure(section, length, n, Components::Planar, support.clone()));
        let unit = modes(&structure(
            samples::euler_bernoulli_section(),
            1.0,
            n,
            Components::Planar,
            support,
        ));
        prop_assert_eq!(b.n_rigid(), if clamped { 0 } else { 3 });
        let (w, w1) = (of_kind(&b, ModeKind::BendingE2), of_kind(&unit, ModeKind::BendingE2));
        prop_assert_eq!(w.len(), w1.len());
        let scale = length * length * (m / ei).sqrt();
        for k in 0..3 {
            let r = w[k] * scale / w1[k] - 1.0;
            prop_assert!(r.abs() < ROUND_OFF, "mode {}: {}", k, r);
        }
    }
}

/// The route does not depend on the coordinates: rotating each node's `(v3, ω2)` pair (a
/// non-diagonal, singular `B1` with no zero diagonal entry: massless directions found by the
/// eigen decomposition of `B1`, not by zero entries) leaves the spectrum, the rigid count and
/// the mode count unchanged to round-off.
#[test]
fn rotated_coordinates_give_the_same_modes() {
    use faer::Mat;
    use modal_rom::{solve_second_order as solve, EigenSettings, SecondOrderProblem};
    for (support, n) in [(Some(JointKind::Weld), 40usize), (None, 33), (Some(JointKind::Ball), 57)]
    {
        let s = structure(samples::euler_bernoulli_section(), 1.0, n, Components::Planar, support);
        let model = StructureModel::new(&s).unwrap();
        let p = &model.problem;
        let n1 = p.n1();
        let mut q = Mat::<f64>::identity(n1, n1);
        for node in 0..=n {
            let (i, j) = (model.layout.x1_index(0, node, 1), model.layout.x1_index(0, node, 2));
            let a = 0.3 + 0.01 * node as f64;
            let (c, sn) = (a.cos(), a.sin());
            q[(i, i)] = c;
            q[(i, j)] = -sn;
            q[(j, i)] = sn;
            q[(j, j)] = c;
        }
        let mut b1 = q.transpose() * &p.b1 * &q;
        for jj in 0..n1 {
            for ii in 0..jj {
                let m = 0.5 * (b1[(ii, jj)] + b1[(jj, ii)]);
                b1[(ii, jj)] = m;
                b1[(jj, ii)] = m;
            }
        }
        let rotated =
            SecondOrderProblem::new(b1, p.b2.clone(), q.transpose() * &p.d, &p.g * &q).unwrap();
        let settings = EigenSettings::default();
        let (a, b) =
            (solve(p, &settings, None).unwrap(), solve(&rotated, &settings, None).unwrap());
        assert_eq!(a.n_rigid, b.n_rigid, "{n} elements");
        assert_eq!(a.omega.len(), b.omega.len(), "{n} elements");
        for k in a.n_rigid..a.n_rigid + 6 {
            let r = b.omega[k] / a.omega[k] - 1.0;
            assert!(r.abs() < ROUND_OFF, "{n} elements, mode {k}: {r:e}");
        }
    }
}

/// A massless direction without stiffness (a mechanism with no dynamics) is a clear error.
#[test]
fn massless_mechanism_is_an_error() {
    use faer::Mat;
    use modal_rom::{solve_second_order as solve, EigenSettings, SecondOrderProblem};
    // coordinate 0: mass 1 on a spring (D = 1, B2 = 1); coordinate 1: massless, no strain;
    // once alone (its own block), once tied to coordinate 0 by a velocity row x0 − x1 = 0 …
    let b1 = Mat::from_fn(2, 2, |i, j| if i == 0 && j == 0 { 1.0 } else { 0.0 });
    let b2 = Mat::from_fn(1, 1, |_, _| 1.0);
    let d = Mat::from_fn(2, 1, |i, _| if i == 0 { 1.0 } else { 0.0 });
    let alone =
        SecondOrderProblem::new(b1.clone(), b2.clone(), d.clone(), Mat::zeros(0, 2)).unwrap();
    let e = solve(&alone, &EigenSettings::default(), None).unwrap_err();
    assert!(e.to_string().contains("massless"), "{e}");
    // … which makes it a slave of the massive one: the direction (1, 1) has mass 1 and
    // stiffness 1, ω = 1, no error.
    let tied = Mat::from_fn(1, 2, |_, j| if j == 0 { 1.0 } else { -1.0 });
    let modes =
        solve(&SecondOrderProblem::new(b1, b2, d, tied).unwrap(), &EigenSettings::default(), None)
            .unwrap();
    assert_eq!(modes.omega.len(), 1);
    assert!((modes.omega[0] - 1.0).abs() < 1e-14, "ω = {}", modes.omega[0]);
}
