//! Unit tests of the modal model on the paper's structures (beam + multibody crates' operators).

use crate::basis::{BasisSettings, ModeKind, ModeSelection};
use crate::rom::RomOptions;
use crate::samples::{self, paper_2d_selection, paper_3d_selection};
use crate::testing;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use std::sync::OnceLock;

fn rom2d() -> &'static samples::Sample {
    static S: OnceLock<samples::Sample> = OnceLock::new();
    S.get_or_init(|| {
        samples::paper_2d(20, 0.0, false, &paper_2d_selection(), &RomOptions::default()).unwrap()
    })
}

fn rom3d() -> &'static samples::Sample {
    static S: OnceLock<samples::Sample> = OnceLock::new();
    S.get_or_init(|| {
        samples::paper_3d(10, 0.3, false, &paper_3d_selection(), &RomOptions::default()).unwrap()
    })
}

#[test]
fn structure_operators_match_the_independent_assembly() {
    // The multibody crate's G and the beam crate's operators against testing.rs (theory.md §2–3).
    for angle in [0.0, 0.7] {
        let s =
            samples::paper_2d(12, angle, false, &ModeSelection::Lowest(12), &RomOptions::default())
                .unwrap();
        let (layout, p) = testing::two_link_2d(12, angle);
        let b =
            crate::basis::ModalBasis::compute(layout, &p, &BasisSettings::default(), None).unwrap();
        assert_eq!(s.basis.n_rigid(), 2);
        for j in 2..12 {
            let (a, c) = (s.basis.lambda()[j], b.lambda()[j]);
            // eigenvalues of a symmetric problem carry an absolute error ~ ε·λmax (λmax ≈ 1e10
            // here: thickness-shear GA/ρI), so compare ω² to that scale
            let tol = 64.0 * f64::EPSILON * b.lambda_max();
            assert!((a - c).abs() <= tol, "angle {angle} mode {j}: {a} vs {c} (tol {tol})");
        }
    }
}

#[test]
fn paper_sets_and_quaternion_mode_counts() {
    let s = rom2d();
    assert_eq!(s.rom.n_modes(), 10);
    assert_eq!(s.rom.n_rigid(), 2);
    assert_eq!(s.rom.n_q2(), 8);
    // ξ̄ + 2 rigid + 4 bending; axial modes of the straight structure rotate nothing.
    assert_eq!(s.rom.n_xi(), 7);
    let s3 =
        samples::paper_3d(10, 0.0, false, &paper_3d_selection(), &RomOptions::default()).unwrap();
    assert_eq!(s3.basis.n_rigid(), 4);
    assert_eq!(s3.rom.n_xi(), 17, "3D: 17 of 21 quaternion modes kept");
    let kinds = s3.rom.kinds();
    assert_eq!(kinds.iter().filter(|k| **k == ModeKind::Torsion).count(), 4);
}

#[test]
fn damping_is_symmetric_negative_semidefinite() {
    let s =
        samples::paper_2d(20, 0.0, true, &paper_2d_selection(), &RomOptions::default()).unwrap();
    let sig = s.rom.sigma();
    let eig = sig.self_adjoint_eigenvalues(faer::Side::Lower).unwrap();
    let scale = eig.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(scale > 0.0);
    assert!(eig.iter().all(|v| *v <= 1e-12 * scale), "{eig:?}");
    for i in 0..s.rom.n_rigid() {
        for j in 0..s.rom.n_modes() {
            assert!(sig[(i, j)].abs() <= 1e-12 * scale, "rigid modes are undamped");
        }
    }
}

fn state(seed: &[f64], n: usize) -> Vec<f64> {
    (0..n).map(|i| seed[i % seed.len()] * (1.0 + 0.37 * i as f64).sin()).collect()
}

#[test]
fn midpoint_conserves_modal_energy() {
    for s in [rom2d(), rom3d()] {
        let rom = &s.rom;
        let mut q = rom.reference_state();
        let init = state(&[0.8, -0.5, 0.3], rom.xi_offset());
        q[..rom.xi_offset()].copy_from_slice(&init);
        let u = vec![0.0; rom.n_inputs()];
        let e0 = rom.energy(&q);
        for _ in 0..200 {
            rom.midpoint_step(&mut q, &u, 0.01, 1e-14, 30).unwrap();
        }
        let drift = (rom.energy(&q) - e0).abs() / e0;
        // midpoint conserves quadratic invariants exactly; what is left is Newton's 1e-14
        // stopping tolerance and round-off over 200 steps
        assert!(drift < 1e-12, "relative drift {drift}");
    }
}

fn cfg() -> Config {
    Config { cases: 64, rng_seed: RngSeed::Fixed(20_261_121), ..Config::default() }
}

proptest! {
    #![proptest_config(cfg())]

    #[test]
    fn energy_neutrality_of_the_quadratic_terms(v in prop::collection::vec(-2.0f64..2.0, 60)) {
        for s in [rom2d(), rom3d()] {
            let rom = &s.rom;
            let q = state(&v, rom.n_state());
            let n = rom.energy_neutrality(&q).unwrap();
            let scale = rom.gamma1().max_abs().max(rom.gamma2().max_abs())
                * q.iter().map(|x| x.abs()).sum::<f64>().powi(3);
            // exact in arithmetic; round-off of the sum of ~nnz products
            prop_assert!(n.abs() <= 1e-14 * scale, "qᵀN(q)q = {n} (scale {scale})");
        }
    }

    #[test]
    fn jacobian_matches_central_differences(v in prop::collection::vec(-1.5f64..1.5, 60), w in prop::collection::vec(-3.0f64..3.0, 5)) {
        for s in [rom2d(), rom3d()] {
            let rom = &s.rom;
            let n = rom.n_state();
            let q = state(&v, n);
            let u: Vec<f64> = (0..rom.n_inputs()).map(|i| w[i % w.len()]).collect();
            let mut jq = vec![0.0; n * n];
            let mut ju = vec![0.0; n * rom.n_inputs()];
            rom.jacobian(&q, &u, &mut jq, &mut ju).unwrap();
            let h = 1e-5;
            let (mut fp, mut fm) = (vec![0.0; n], vec![0.0; n]);
            let mut worst = 0.0f64;
            let mut scale = 1.0f64;
            for c in 0..n + rom.n_inputs() {
                let (mut qp, mut qm, mut up, mut um) = (q.clone(), q.clone(), u.clone(), u.clone());
                if c < n { qp[c] += h; qm[c] -= h; } else { up[c - n] += h; um[c - n] -= h; }
                rom.rhs(&qp, &up, &mut fp).unwrap();
                rom.rhs(&qm, &um, &mut fm).unwrap();
                for r in 0..n {
                    let fd = (fp[r] - fm[r]) / (2.0 * h);
                    let exact = if c < n { jq[c * n + r] } else { ju[(c - n) * n + r] };
                    worst = worst.max((fd - exact).abs());
                    scale = scale.max(exact.abs());
                }
            }
            // f is quadratic: central differences are exact up to round-off ε|f|/h
            prop_assert!(worst <= 1e-8 * scale, "FD mismatch {worst} (scale {scale})");
            // the fused evaluation gives the same numbers
            let (mut f2, mut jq2, mut ju2) = (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * rom.n_inputs()]);
            rom.rhs_and_jacobian(&q, &u, &mut f2, &mut jq2, &mut ju2).unwrap();
            let mut f1 = vec![0.0; n];
            rom.rhs(&q, &u, &mut f1).unwrap();
            let dev = f1.iter().zip(&f2).chain(jq.iter().zip(&jq2)).chain(ju.iter().zip(&ju2)).fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
            prop_assert!(dev <= 1e-13 * scale, "fused evaluation differs by {dev}");
            // Hessian: central differences of the Jacobian contracted with weights
            let wts: Vec<f64> = (0..n).map(|i| (i as f64 * 1.3).cos()).collect();
            let nt = n + rom.n_inputs();
            let mut hess = vec![0.0; nt * nt];
            rom.weighted_hessian(&wts, &mut hess).unwrap();
            let (mut jp, mut jm, mut up_, mut um_) = (vec![0.0; n * n], vec![0.0; n * n], vec![0.0; n * rom.n_inputs()], vec![0.0; n * rom.n_inputs()]);
            let mut hworst = 0.0f64;
            for c in 0..n {
                let (mut qp, mut qm) = (q.clone(), q.clone());
                qp[c] += h;
                qm[c] -= h;
                rom.jacobian(&qp, &u, &mut jp, &mut up_).unwrap();
                rom.jacobian(&qm, &u, &mut jm, &mut um_).unwrap();
                for a in 0..n {
                    let fd: f64 = (0..n).map(|r| wts[r] * (jp[a * n + r] - jm[a * n + r]) / (2.0 * h)).sum();
                    hworst = hworst.max((fd - hess[c * nt + a]).abs());
                }
            }
            prop_assert!(hworst <= 1e-7 * scale, "Hessian mismatch {hworst}");
        }
    }

    #[test]
    fn project_reconstruct_project_round_trip(v in prop::collection::vec(-1.0f64..1.0, 60)) {
        for s in [rom2d(), rom3d()] {
            let rom = &s.rom;
            let mut q = state(&v, rom.n_state());
            // a unit-ish quaternion field: qξ near e0
            let ox = rom.xi_offset();
            for i in ox..rom.n_state() { q[i] *= 0.1; }
            q[ox] = 1.0;
            let f = rom.reconstruct(&q).unwrap();
            // raw (unnormalised) quaternion field for the round trip
            let qm = rom.quaternion().unwrap();
            let raw: Vec<[f64; 4]> = (0..qm.weights.len()).map(|n| {
                let mut a = [0.0; 4];
                for (c, x) in a.iter_mut().enumerate() {
                    *x = (0..qm.kept.len()).map(|k| qm.phi_xi[(4 * n + c, k)] * q[ox + k]).sum();
                }
                a
            }).collect();
            let back = rom.project(&f.x1, &f.x2, Some(&raw)).unwrap();
            let err = q.iter().zip(&back).fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
            prop_assert!(err < 1e-10, "round trip error {err}");
        }
    }
}

#[test]
fn reference_state_reconstructs_the_reference_geometry() {
    for s in [rom2d(), rom3d()] {
        let rom = &s.rom;
        let q = rom
            .project(&vec![0.0; rom.layout().n1()], &vec![0.0; rom.layout().n2()], None)
            .unwrap();
        let r = rom.reference_state();
        let err = q.iter().zip(&r).fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        assert!(err < 1e-12, "undeformed field projects to qξ = e0: {err}");
        let pos = rom.positions(&q).unwrap();
        for (b, beam) in rom.layout().beams.iter().enumerate() {
            for n in 0..beam.n_nodes() {
                let d: f64 = (0..3)
                    .map(|a| (pos[b][n][a] - beam.reference_positions[n][a]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                assert!(d < 1e-12, "beam {b} node {n}: {d}");
            }
        }
    }
}

#[test]
fn export_then_read_is_identical() {
    for s in [rom2d(), rom3d()] {
        let rom = &s.rom;
        let dir = std::env::temp_dir().join(format!(
            "modal-rom-export-{}-{}",
            std::process::id(),
            rom.n_modes()
        ));
        let meta = rom.export(&dir).unwrap();
        assert_eq!(meta.frequencies_rad_s, rom.omega());
        let back = crate::rom::ModalRom::read(&dir).unwrap();
        assert_eq!(back.omega(), rom.omega());
        assert_eq!(back.sigma(), rom.sigma());
        assert_eq!(back.gamma1(), rom.gamma1());
        assert_eq!(back.gamma2(), rom.gamma2());
        assert_eq!(back.b_u(), rom.b_u());
        let (a, b) = (back.quaternion().unwrap(), rom.quaternion().unwrap());
        assert_eq!(a.a_xi, b.a_xi);
        assert_eq!(a.gamma_xi, b.gamma_xi);
        assert_eq!(a.gamma_xi_scaled, b.gamma_xi_scaled);
        assert_eq!(a.phi_xi, b.phi_xi);
        // same dynamics, bit for bit
        let q: Vec<f64> = (0..rom.n_state()).map(|i| (i as f64 * 0.7).sin()).collect();
        let u: Vec<f64> = (0..rom.n_inputs()).map(|i| i as f64 - 1.0).collect();
        let (mut f1, mut f2) = (vec![0.0; rom.n_state()], vec![0.0; rom.n_state()]);
        rom.rhs(&q, &u, &mut f1).unwrap();
        back.rhs(&q, &u, &mut f2).unwrap();
        assert_eq!(f1, f2);
        let x = rom.reconstruct(&q).unwrap();
        assert_eq!(
            back.project(&x.x1, &x.x2, None).unwrap(),
            rom.project(&x.x1, &x.x2, None).unwrap()
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}

#[test]
fn reading_a_corrupted_export_is_an_error() {
    let rom = &rom2d().rom;
    let dir = std::env::temp_dir().join(format!("modal-rom-bad-{}", std::process::id()));
    rom.export(&dir).unwrap();
    std::fs::write(
        dir.join("sigma.npy"),
        crate::npy::to_bytes(&crate::npy::NpyArray { shape: vec![2], data: vec![0.0; 2] }),
    )
    .unwrap();
    let err = crate::rom::ModalRom::read(&dir).unwrap_err().to_string();
    assert!(err.contains("sigma"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn mode_report_lists_rigid_then_elastic() {
    let structure =
        multibody_constraints::samples::paper_2d(intrinsic_beam::Section::paper_2d(), 20, 0.0)
            .unwrap();
    let r = crate::report::mode_report(&structure, 7, &BasisSettings::default()).unwrap();
    assert_eq!(r.labels[..2], ["rigid".to_string(), "rigid".to_string()]);
    assert_eq!(r.frequencies_rad_s[..2], [0.0, 0.0]);
    assert!(r.frequencies_rad_s.windows(2).all(|w| w[0] <= w[1]));
    assert_eq!(r.shapes[3].beams.len(), 2);
    let json = serde_json::to_value(&r).unwrap();
    assert!(json["frequencies_rad_s"].is_array() && json["labels"].is_array());
}

#[test]
fn joint_torque_input_matches_the_plant() {
    // A small elbow torque for 0.1 s: the ROM's joint-torque column of B_u must move the
    // structure as the plant's joint torque does (same sign and size, small angles).
    use multibody_constraints::{Plant, PlantSettings};
    let n = 10;
    let structure =
        multibody_constraints::samples::paper_2d(intrinsic_beam::Section::paper_2d(), n, 0.0)
            .unwrap();
    let model = crate::structure::StructureModel::new(&structure).unwrap();
    let basis = model.modes(&BasisSettings::default()).unwrap();
    let sel = basis.select(&ModeSelection::Lowest(16)).unwrap();
    let inputs = vec![
        model.joint_torque(&structure, "elbow torque", "elbow", None).unwrap(),
        model.joint_torque(&structure, "root torque", "root", None).unwrap(),
    ];
    let rom =
        crate::rom::ModalRom::new(&sel, Some(&model.damping), &inputs, &RomOptions::default())
            .unwrap();
    for (c, joint) in ["elbow", "root"].iter().enumerate() {
        let mut plant =
            Plant::new(structure.clone(), PlantSettings { dt: 2e-3, ..PlantSettings::default() })
                .unwrap();
        plant.set_joint_torque(joint, None, 0.01).unwrap();
        let mut q = rom.reference_state();
        let mut u = vec![0.0; 2];
        u[c] = 0.01;
        for _ in 0..50 {
            plant.step().unwrap();
            rom.midpoint_step(&mut q, &u, 2e-3, 1e-12, 30).unwrap();
        }
        let fe = rom.project_full(plant.state(), None).unwrap();
        let scale = q[..rom.n_modes()].iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let diff = (0..rom.n_modes()).fold(0.0f64, |a, i| a.max((q[i] - fe[i]).abs()));
        // small motion (angles ~1e-3): truncation and geometric nonlinearity at the 1 % level
        assert!(
            scale > 0.0 && diff < 0.02 * scale,
            "{joint}: q1 differs by {diff} (scale {scale})"
        );
    }
}

#[test]
fn options_without_quaternions_and_with_rigid_q2() {
    let opts =
        RomOptions { rigid_q2: true, quaternions: false, damping: false, ..RomOptions::default() };
    let s = samples::paper_2d(12, 0.2, true, &ModeSelection::Lowest(8), &opts).unwrap();
    let rom = &s.rom;
    assert_eq!(rom.n_xi(), 0);
    assert_eq!(rom.n_q2(), 8);
    assert_eq!(rom.n_state(), 16);
    assert!(rom.sigma().as_ref().norm_max() == 0.0, "damping switched off");
    let q: Vec<f64> = (0..16).map(|i| (i as f64 * 0.9).cos()).collect();
    let u = vec![0.1, -0.2, 0.3];
    let n = rom.energy_neutrality(&q).unwrap();
    assert!(n.abs() < 1e-12 * rom.gamma1().max_abs().max(rom.gamma2().max_abs()) * 1e3);
    // rigid q2 stay at 0 (φ2 ≡ 0, ω = 0): their rates vanish
    let mut f = vec![0.0; 16];
    rom.rhs(&q, &u, &mut f).unwrap();
    let o2 = rom.q2_offset();
    assert_eq!(f[o2], 0.0);
    assert_eq!(f[o2 + 1], 0.0);
    // bad inputs are errors, not panics or NaN
    assert!(rom.rhs(&q[..5], &u, &mut f).is_err());
    let mut bad = q.clone();
    bad[3] = f64::NAN;
    assert!(rom.rhs(&bad, &u, &mut f).is_err());
    assert!(RomOptions { quaternion_tolerance: 0.0, ..RomOptions::default() }.validate().is_err());
}
