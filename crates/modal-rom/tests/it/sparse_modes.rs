//! The sparse route (shift-invert Lanczos on the saddle-point pencil) against the dense route
//! (SVD on the null space of the constraints): same frequencies, labels and mode shapes on the
//! paper's two-links in 2D and 3D at several joint angles, rigid modes included, every
//! returned pair within the residual tolerance.

use intrinsic_beam::{samples as beam_samples, Components, Section};
use modal_rom::{
    mode_report, solve_sparse, sparse_mode_report, BasisSettings, ModeReport, SparseProblem,
    SparseSettings,
};
use multibody_constraints::{samples, JointKind, Structure};

/// Largest relative difference of the frequencies, the rigid ones compared absolutely
/// against the first elastic frequency.
fn frequency_gap(a: &ModeReport, b: &ModeReport) -> f64 {
    let scale = a.frequencies_rad_s[a.n_rigid];
    a.frequencies_rad_s
        .iter()
        .zip(&b.frequencies_rad_s)
        .map(|(x, y)| (x - y).abs() / x.abs().max(scale))
        .fold(0.0, f64::max)
}

/// Largest difference of the mode shapes, up to sign, relative to each shape's largest entry.
fn shape_gap(a: &ModeReport, b: &ModeReport, from: usize) -> f64 {
    let flat = |r: &ModeReport, j: usize| -> Vec<f64> {
        r.shapes[j].beams.iter().flat_map(|b| b.phi1.iter().flatten().copied()).collect()
    };
    (from..a.shapes.len())
        .map(|j| {
            let (x, y) = (flat(a, j), flat(b, j));
            let m = x.iter().fold(0.0f64, |s, v| s.max(v.abs()));
            let d = |sg: f64| x.iter().zip(&y).fold(0.0f64, |s, (p, q)| s.max((p - sg * q).abs()));
            d(1.0).min(d(-1.0)) / m
        })
        .fold(0.0, f64::max)
}

fn compare(s: &Structure, n_modes: usize, what: &str) {
    let settings = BasisSettings::default();
    let dense = mode_report(s, n_modes, &settings).unwrap();
    let sparse = sparse_mode_report(s, n_modes, &settings, &SparseSettings::default()).unwrap();
    assert_eq!(dense.n_rigid, sparse.n_rigid, "{what}: rigid count");
    assert_eq!(dense.labels, sparse.labels, "{what}: labels");
    let gap = frequency_gap(&dense, &sparse);
    assert!(gap < 1e-8, "{what}: frequencies differ by {gap:e}\n{dense:?}\n{sparse:?}");
    // rigid shapes: the same exact rotations; elastic ones up to sign (simple eigenvalues)
    let shapes = shape_gap(&dense, &sparse, 0);
    eprintln!("{what}: frequency gap {gap:.1e}, shape gap {shapes:.1e}");
    assert!(shapes < 1e-5, "{what}: mode shapes differ by {shapes:e}");
}

#[test]
fn sparse_route_matches_the_dense_route_on_the_2d_two_link() {
    for deg in [0.0f64, 45.0, 90.0] {
        let s = samples::paper_2d(Section::paper_2d(), 40, deg.to_radians()).unwrap();
        compare(&s, 16, &format!("2D at {deg}°"));
    }
}

#[test]
fn sparse_route_matches_the_dense_route_on_the_3d_two_link() {
    for deg in [0.0f64, 30.0] {
        let s = samples::paper_3d(Section::paper_3d(), 20, deg.to_radians()).unwrap();
        compare(&s, 20, &format!("3D at {deg}°"));
    }
}

/// Every returned pair meets the residual tolerance, the rigid count is right, the modes are
/// `B1`-orthonormal, and the run is bit-for-bit repeatable.
#[test]
fn residuals_orthonormality_and_repeatability() {
    let s = samples::paper_2d(Section::paper_2d(), 60, 0.3).unwrap();
    let (layout, problem, candidates) = SparseProblem::of_structure(&s).unwrap();
    let settings = SparseSettings::default();
    let run = || {
        solve_sparse(
            &problem,
            layout.k(),
            12,
            &BasisSettings::default(),
            &settings,
            Some(candidates.as_ref()),
        )
        .unwrap()
    };
    let m = run();
    assert_eq!(m.n_rigid, 2);
    assert_eq!(m.omega.len(), 12);
    for (j, r) in m.residuals.iter().enumerate() {
        assert!(*r <= settings.tolerance, "mode {j}: residual {r:e}");
    }
    assert!(m.omega.windows(2).all(|w| w[0] <= w[1]), "{:?}", m.omega);
    let dense = problem.to_dense().unwrap();
    let g = m.phi1.transpose() * &dense.b1 * &m.phi1;
    for i in 0..12 {
        for j in 0..12 {
            let want = if i == j { 1.0 } else { 0.0 };
            assert!((g[(i, j)] - want).abs() < 1e-9, "Φ1ᵀB1Φ1[{i},{j}] = {}", g[(i, j)]);
        }
    }
    // ⟨φ1i, D φ2j⟩ = ω_j δij on the elastic modes (the paper's sign, eq. 15)
    let dd = m.phi1.transpose() * &dense.d * &m.phi2;
    for i in 2..12 {
        for j in 2..12 {
            let want = if i == j { m.omega[j] } else { 0.0 };
            assert!((dd[(i, j)] - want).abs() < 1e-7 * m.omega[11], "Φ1ᵀDΦ2[{i},{j}]");
        }
    }
    let again = run();
    assert_eq!(
        m.omega.iter().map(|w| w.to_bits()).collect::<Vec<_>>(),
        again.omega.iter().map(|w| w.to_bits()).collect::<Vec<_>>()
    );
}

/// Euler–Bernoulli cantilever (rigid shear, massless rotation): the saddle-point solve
/// condenses the massless rotations; the sparse route gives the dense route's frequencies.
#[test]
fn euler_bernoulli_cantilever_matches_the_dense_route() {
    let section = beam_samples::euler_bernoulli_section();
    let beam = intrinsic_beam::Beam::new(
        section,
        intrinsic_beam::Mesh::uniform(1.0, 60).unwrap(),
        Components::Planar,
    )
    .unwrap();
    let s = Structure::new(
        vec![multibody_constraints::StructureBeam::new(
            "beam",
            beam,
            multibody_constraints::Placement::origin(),
        )],
        vec![],
        vec![multibody_constraints::Support {
            name: "root".into(),
            end: multibody_constraints::EndRef::new("beam", multibody_constraints::End::Start),
            kind: JointKind::Weld,
        }],
        multibody_constraints::StructureSettings::default(),
    )
    .unwrap();
    let settings = BasisSettings::default();
    let dense = mode_report(&s, 8, &settings).unwrap();
    let sparse = sparse_mode_report(&s, 8, &settings, &SparseSettings::default()).unwrap();
    assert_eq!(dense.labels, sparse.labels);
    let gap = frequency_gap(&dense, &sparse);
    assert!(gap < 1e-8, "{gap:e}\n{:?}\n{:?}", dense.frequencies_rad_s, sparse.frequencies_rad_s);
}
