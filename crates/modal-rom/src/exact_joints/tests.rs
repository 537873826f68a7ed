//! Identities of the exact-joints model (theory.md §10): reduction to the paper's model at the
//! reference rotation, energy neutrality, compatibility, exact Jacobian against finite
//! differences, energy conservation of the implicit midpoint rule.

use super::*;
use crate::basis::ModeSelection;
use crate::samples::{self, paper_2d_selection, paper_3d_selection};
use crate::{BasisSettings, RomOptions};
use intrinsic_beam::Section;
use nalgebra::Vector4;
use proptest::prelude::*;
use std::sync::OnceLock;

fn paper_options() -> RomOptions {
    RomOptions { quaternions: false, ..RomOptions::default() }
}

/// Link fields from the constrained modes (rigid + `elastic` lowest) at `angles`, plus rigid
/// link motions: the multi-angle basis of theory.md §10.6.
fn multi_angle(
    spatial: bool,
    n: usize,
    damped: bool,
    angles: &[f64],
    elastic: usize,
    keep_support_rows: bool,
) -> ExactJointsRom {
    let section = match (spatial, damped) {
        (false, true) => Section::paper_2d(),
        (false, false) => Section::paper_2d().undamped(),
        (true, true) => Section::paper_3d(),
        (true, false) => Section::paper_3d().undamped(),
    };
    let build = |a: f64| {
        if spatial {
            multibody_constraints::samples::paper_3d(section.clone(), n, a)
        } else {
            multibody_constraints::samples::paper_2d(section.clone(), n, a)
        }
        .unwrap()
    };
    let structure = build(0.0);
    let model = StructureModel::new(&structure).unwrap();
    let mut fields = Vec::new();
    for &a in angles {
        let s = build(a);
        let m = StructureModel::new(&s).unwrap();
        let b = m.modes(&BasisSettings::default()).unwrap();
        let sel = b.select(&ModeSelection::Lowest(b.n_rigid() + elastic)).unwrap();
        fields.push(sel.phi1().to_owned());
    }
    let refs: Vec<_> = fields.iter().map(|f| f.as_ref()).collect();
    let inputs = if spatial {
        samples::inputs_3d(&structure, &model).unwrap()
    } else {
        samples::inputs_2d(&structure, &model).unwrap()
    };
    let damping = damped.then_some(&model.damping);
    let basis = LinkBasis::from_fields(&model, &refs, &LinkBasisSettings::default()).unwrap();
    if keep_support_rows {
        ExactJointsRom::new_keeping_support_rows(&structure, basis, damping, &inputs).unwrap()
    } else {
        ExactJointsRom::new(&structure, basis, damping, &inputs).unwrap()
    }
}

fn undamped_2d() -> &'static ExactJointsRom {
    static ROM: OnceLock<ExactJointsRom> = OnceLock::new();
    ROM.get_or_init(|| multi_angle(false, 6, false, &[0.0, 0.8, 1.6], 3, false))
}

fn damped_3d() -> &'static ExactJointsRom {
    static ROM: OnceLock<ExactJointsRom> = OnceLock::new();
    ROM.get_or_init(|| multi_angle(true, 4, true, &[0.0, 0.8], 2, false))
}

/// A state with velocities `p`, forces `p2` from `seed`, the elbow turned by `angle` about
/// `axis` from its reference.
fn state(rom: &ExactJointsRom, seed: f64, angle: f64, axis: [f64; 3], scale: f64) -> Vec<f64> {
    let mut x = rom.reference_state();
    for (i, v) in x[..rom.n_p() + rom.n_p2()].iter_mut().enumerate() {
        *v = scale * (seed * (i as f64 + 1.3)).sin();
    }
    let a = nalgebra::Vector3::from(axis).normalize() * (0.5 * angle).sin();
    let turn = Vector4::new((0.5 * angle).cos(), a.x, a.y, a.z);
    let o = rom.joint_offset(0);
    let r = rom.joint_quaternion(&x, 0);
    let q = super::rows::quat_mul(&r, &turn);
    x[o..o + 4].copy_from_slice(q.as_slice());
    x
}

/// The paper's damped two-link (3D on 6, 2D on 8 elements per link) at the reference angle
/// with the paper's mode set, and that set's basis.
fn paper_sample(spatial: bool) -> (samples::Sample, ModalBasis) {
    let (sample, selection) = if spatial {
        let selection = paper_3d_selection();
        (samples::paper_3d(6, 0.0, true, &selection, &paper_options()).unwrap(), selection)
    } else {
        let selection = paper_2d_selection();
        (samples::paper_2d(8, 0.0, true, &selection, &paper_options()).unwrap(), selection)
    };
    let modes = sample.basis.select(&selection).unwrap();
    (sample, modes)
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// At the reference rotation, with the paper's basis, right-hand side and
/// `(q1, q2, u)` Jacobian equal the paper model's (2D and 3D, damped).
#[test]
fn reduces_to_the_paper_model_at_the_reference_rotation() {
    for spatial in [false, true] {
        let (sample, modes) = paper_sample(spatial);
        let inputs = if spatial {
            samples::inputs_3d(&sample.structure, &sample.model).unwrap()
        } else {
            samples::inputs_2d(&sample.structure, &sample.model).unwrap()
        };
        let ej = paper_reduction(
            &sample.structure,
            &sample.model,
            &modes,
            Some(&sample.model.damping),
            &inputs,
        )
        .unwrap();
        let paper = &sample.rom;
        let np = paper.n_state();
        assert_eq!(ej.n_p() + ej.n_p2(), np);
        let nu = paper.n_inputs();
        for seed in [0.37, 1.1, 2.9] {
            let mut x = ej.reference_state();
            for (i, v) in x[..np].iter_mut().enumerate() {
                *v = 0.4 * (seed * (i as f64 + 0.7)).sin();
            }
            let u: Vec<f64> = (0..nu).map(|i| (seed + i as f64).cos()).collect();
            let q = x[..np].to_vec();
            let (mut f0, mut j0, mut ju0) = (vec![0.0; np], vec![0.0; np * np], vec![0.0; np * nu]);
            paper.rhs_and_jacobian(&q, &u, &mut f0, &mut j0, &mut ju0).unwrap();
            let n = ej.n_state();
            let (mut f1, mut j1, mut ju1) = (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]);
            ej.rhs_and_jacobian(&x, &u, &mut f1, &mut j1, &mut ju1).unwrap();
            let fs = max_abs(&f0);
            let df = (0..np).fold(0.0f64, |m, i| m.max((f0[i] - f1[i]).abs()));
            let js = max_abs(&j0);
            let mut dj = 0.0f64;
            for c in 0..np {
                for r in 0..np {
                    dj = dj.max((j0[c * np + r] - j1[c * n + r]).abs());
                }
            }
            let mut du = 0.0f64;
            for c in 0..nu {
                for r in 0..np {
                    du = du.max((ju0[c * np + r] - ju1[c * n + r]).abs());
                }
            }
            eprintln!(
                "spatial {spatial}: |Δf|/|f| {:.1e}, |ΔJ|/|J| {:.1e}, |ΔB| {du:.1e}",
                df / fs,
                dj / js
            );
            // normwise relative (theory.md §10.6): measured ≤ 6.2e-14 (rhs), ≤ 2.5e-14
            // (Jacobian), ≤ 3.6e-15 (inputs), 2D and 3D; needs link fields orthonormal to
            // round-off and the modes' `Φ2` re-expanded exactly (force fields = their pieces)
            assert!(df <= 1e-12 * fs, "rhs differs: {df:e} of {fs:e}");
            assert!(dj <= 1e-12 * js, "Jacobian differs: {dj:e} of {js:e}");
            assert!(du <= 1e-12 * max_abs(&ju0));
        }
    }
}

/// The exact Jacobian against central differences (of `rhs`, which applies `Z(ξ)` through its
/// factors while the Jacobian forms it), away from the reference rotation.
#[test]
fn jacobian_matches_finite_differences() {
    let cases = [(undamped_2d(), [0.0, 1.0, 0.0]), (damped_3d(), [0.2, 1.0, -0.6])];
    for ((rom, axis), norm) in cases.into_iter().flat_map(|c| [(c, 1.0), (c, 1.15)]) {
        let mut x = state(rom, 0.71, 1.3, axis, 0.3);
        let o = rom.joint_offset(0);
        x[o..o + 4].iter_mut().for_each(|v| *v *= norm);
        let n = rom.n_state();
        let nu = rom.n_inputs();
        let u: Vec<f64> = (0..nu).map(|i| 0.3 * (i as f64 + 1.0)).collect();
        let (mut f, mut jx, mut ju) = (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]);
        rom.rhs_and_jacobian(&x, &u, &mut f, &mut jx, &mut ju).unwrap();
        // the right-hand side alone (no `Z` formed) is the same computation of `f`
        let mut f_alone = vec![0.0; n];
        rom.rhs(&x, &u, &mut f_alone).unwrap();
        assert_eq!(f, f_alone, "rhs and rhs_and_jacobian must give the same f");
        let h = 1e-6;
        let mut worst = 0.0f64;
        let scale = max_abs(&jx).max(1.0);
        let (mut fp, mut fm) = (vec![0.0; n], vec![0.0; n]);
        for c in 0..n {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[c] += h;
            xm[c] -= h;
            rom.rhs(&xp, &u, &mut fp).unwrap();
            rom.rhs(&xm, &u, &mut fm).unwrap();
            for r in 0..n {
                let fd = (fp[r] - fm[r]) / (2.0 * h);
                worst = worst.max((fd - jx[c * n + r]).abs() / scale);
            }
        }
        for c in 0..nu {
            let (mut up, mut um) = (u.clone(), u.clone());
            up[c] += h;
            um[c] -= h;
            rom.rhs(&x, &up, &mut fp).unwrap();
            rom.rhs(&x, &um, &mut fm).unwrap();
            for r in 0..n {
                let fd = (fp[r] - fm[r]) / (2.0 * h);
                worst = worst.max((fd - ju[c * n + r]).abs() / scale);
            }
        }
        eprintln!("n = {n}, |ξ| = {norm}: max |J − FD| / max|J| = {worst:.2e}");
        assert!(worst < 1e-7, "Jacobian vs FD: {worst:e}");
    }
}

/// The support rows are constant: reducing the fields to their null space once (the model's
/// construction) gives the same model as keeping them as rows of `A(ξ)`, in the same
/// coordinates `p` (theory.md §10.4). 2D: the reduced model's planar evaluation against the
/// unreduced one's general evaluation; 3D: both general.
#[test]
fn support_reduction_gives_the_same_model() {
    let cases = [
        (undamped_2d(), multi_angle(false, 6, false, &[0.0, 0.8, 1.6], 3, true), [0.0, 1.0, 0.0]),
        (damped_3d(), multi_angle(true, 4, true, &[0.0, 0.8], 2, true), [0.2, 1.0, -0.6]),
    ];
    for (reduced, kept, axis) in &cases {
        assert_eq!(reduced.cons.support.nrows(), 0);
        assert!(kept.cons.support.nrows() > 0);
        assert!(reduced.basis().n1() < kept.basis().n1());
        let (n, nu) = (kept.n_state(), kept.n_inputs());
        assert_eq!((reduced.n_state(), reduced.n_inputs()), (n, nu));
        let mut worst = [0.0f64; 3];
        for (seed, angle) in [(0.37, 0.0), (0.71, 1.3), (1.9, -2.4)] {
            let x = state(kept, seed, angle, *axis, 0.3);
            let u: Vec<f64> = (0..nu).map(|i| 0.3 * (i as f64 + 1.0)).collect();
            let mut out: [_; 2] =
                std::array::from_fn(|_| (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]));
            for (rom, (f, jx, ju)) in [reduced, kept].into_iter().zip(&mut out) {
                rom.rhs_and_jacobian(&x, &u, f, jx, ju).unwrap();
            }
            let [(f0, jx0, ju0), (f1, jx1, ju1)] = &out;
            for (w, (a, b)) in worst.iter_mut().zip([(f0, f1), (jx0, jx1), (ju0, ju1)]) {
                let d = a.iter().zip(b).fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
                *w = w.max(d / max_abs(b).max(1e-300));
            }
        }
        eprintln!(
            "n = {n}, fields {} → {}, rows {} → {}: rhs / ∂f/∂x / ∂f/∂u {worst:?}",
            kept.basis().n1(),
            reduced.basis().n1(),
            kept.cons.n_rows(),
            reduced.cons.n_rows()
        );
        assert!(worst.iter().all(|&w| w < 1e-12), "{worst:?}");
    }
}

/// A zero joint quaternion is no rotation: an error naming it, not a NaN.
#[test]
fn a_zero_joint_quaternion_is_an_error() {
    let rom = undamped_2d();
    let mut x = state(rom, 0.3, 0.4, [0.0, 1.0, 0.0], 0.5);
    let o = rom.joint_offset(0);
    x[o..o + 4].fill(0.0);
    let mut f = vec![0.0; rom.n_state()];
    let e = rom.rhs(&x, &vec![0.0; rom.n_inputs()], &mut f).unwrap_err().to_string();
    assert!(e.contains("joint quaternion 0"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    /// The rows read a joint quaternion through its unit rotation (theory.md §10.3): scaling
    /// `ξ_j` by `λ` leaves every rate but `ξ̇_j` unchanged and scales `ξ̇_j` by `λ`, and the
    /// Jacobian's radial column `(∂f/∂ξ_j) ξ_j` is `ξ̇_j` in joint `j`'s rows and zero elsewhere;
    /// 2D (planar evaluation) and 3D (general).
    #[test]
    fn joint_quaternion_norm_scales_its_own_rate(
        spatial in any::<bool>(),
        seed in 0.1f64..10.0,
        angle in -2.5f64..2.5,
        lambda in 0.5f64..2.0,
    ) {
        let (rom, axis) =
            if spatial { (damped_3d(), [0.2, 1.0, -0.6]) } else { (undamped_2d(), [0.0, 1.0, 0.0]) };
        let x = state(rom, seed, angle, axis, 0.7);
        let o = rom.joint_offset(0);
        let mut xs = x.clone();
        xs[o..o + 4].iter_mut().for_each(|v| *v *= lambda);
        let (n, nu) = (rom.n_state(), rom.n_inputs());
        let u: Vec<f64> = (0..nu).map(|i| 0.2 * (i as f64 + 1.0)).collect();
        let (mut f, mut fs) = (vec![0.0; n], vec![0.0; n]);
        let (mut jx, mut ju) = (vec![0.0; n * n], vec![0.0; n * nu]);
        rom.rhs(&x, &u, &mut f).unwrap();
        rom.rhs_and_jacobian(&xs, &u, &mut fs, &mut jx, &mut ju).unwrap();
        let size = max_abs(&f);
        for i in 0..n {
            let want = if (o..o + 4).contains(&i) { lambda * f[i] } else { f[i] };
            prop_assert!((fs[i] - want).abs() <= 1e-12 * size, "row {i}: {} vs {want}", fs[i]);
            let radial: f64 = (0..4).map(|c| jx[(o + c) * n + i] * xs[o + c]).sum();
            let want = if (o..o + 4).contains(&i) { fs[i] } else { 0.0 };
            prop_assert!((radial - want).abs() <= 1e-12 * max_abs(&jx), "radial row {i}: {radial}");
        }
    }

    /// Energy neutrality (`pᵀṗ + p2ᵀṗ2 = 0` without damping and input) and compatibility
    /// (`A(ξ) Z(ξ) p = 0`) at any state and joint rotation.
    #[test]
    fn energy_neutral_and_compatible(seed in 0.1f64..10.0, angle in -2.5f64..2.5, scale in 0.01f64..3.0) {
        let rom = undamped_2d();
        let x = state(rom, seed, angle, [0.0, 1.0, 0.0], scale);
        let mut f = vec![0.0; rom.n_state()];
        rom.rhs(&x, &vec![0.0; rom.n_inputs()], &mut f).unwrap();
        let k = rom.n_p() + rom.n_p2();
        let power: f64 = (0..k).map(|i| x[i] * f[i]).sum();
        let size: f64 = (0..k).map(|i| (x[i] * f[i]).abs()).sum::<f64>().max(1e-300);
        prop_assert!(power.abs() <= 1e-12 * size, "power {power:e} of {size:e}");
        let res = rom.compatibility_residual(&x).unwrap();
        let v = max_abs(&rom.link_velocities(&x).unwrap());
        prop_assert!(res <= 1e-12 * v.max(1e-300), "compatibility {res:e}");
    }
}

/// The 3D model is energy neutral too (universal joints, elbow turned about a skew axis).
#[test]
fn energy_neutral_3d() {
    let rom = multi_angle(true, 4, false, &[0.0, 0.8], 2, false);
    for (seed, angle) in [(0.3, 0.4), (1.7, 1.4), (2.2, -2.0)] {
        let x = state(&rom, seed, angle, [0.3, 1.0, 0.5], 1.0);
        let mut f = vec![0.0; rom.n_state()];
        rom.rhs(&x, &vec![0.0; rom.n_inputs()], &mut f).unwrap();
        let k = rom.n_p() + rom.n_p2();
        let power: f64 = (0..k).map(|i| x[i] * f[i]).sum();
        let size: f64 = (0..k).map(|i| (x[i] * f[i]).abs()).sum();
        assert!(power.abs() <= 1e-12 * size, "power {power:e} of {size:e}");
        assert!(rom.compatibility_residual(&x).unwrap() < 1e-12);
    }
}

/// Implicit midpoint conserves the energy and `|ξ|` to solver tolerance while the elbow
/// swings through a large angle (short run; the long one is a verification case).
#[test]
fn midpoint_conserves_energy() {
    let rom = undamped_2d();
    let mut x = state(rom, 0.9, 0.0, [0.0, 1.0, 0.0], 0.0);
    // spin link 2 about the elbow: the rigid relative rotation of the reference null space
    let q1 = rom.link_velocities(&x).unwrap();
    assert!(max_abs(&q1) == 0.0);
    x[0] = 1.0;
    x[1] = -0.5;
    let e0 = rom.energy(&x);
    let u = vec![0.0; rom.n_inputs()];
    let mut turned = 0.0f64;
    for _ in 0..200 {
        rom.midpoint_step(&mut x, &u, 0.01, 1e-14, 30).unwrap();
        let q = rom.joint_quaternion(&x, 0);
        turned = turned.max(2.0 * q[2].atan2(q[0]).abs());
    }
    let drift = (rom.energy(&x) - e0).abs() / e0;
    let norm = rom.joint_quaternion(&x, 0).norm();
    eprintln!(
        "energy drift {drift:.2e}, |ξ| − 1 = {:.1e}, max elbow angle {turned:.2}",
        norm - 1.0
    );
    assert!(drift < 1e-12, "energy drift {drift:e}");
    assert!((norm - 1.0).abs() < 1e-12);
    assert!(turned > 0.3, "the elbow should move: {turned}");
}

#[test]
fn bad_coordinates_are_errors() {
    let sample = samples::paper_2d(4, 0.0, false, &paper_2d_selection(), &paper_options()).unwrap();
    let modes = sample.basis.select(&paper_2d_selection()).unwrap();
    let basis = LinkBasis::from_fields(
        &sample.model,
        &[modes.phi1()],
        &LinkBasisSettings { rigid_links: false, ..Default::default() },
    )
    .unwrap();
    let na = basis.n1();
    let z0 = Mat::from_fn(na, 1, |i, _| if i == 0 { 2.0 } else { 0.0 });
    let z2 = Mat::identity(basis.n2(), basis.n2());
    let err =
        ExactJointsRom::with_coordinates(&sample.structure, basis, None, &[], z0, z2).unwrap_err();
    assert!(err.to_string().contains("z0"), "{err}");
    let bad = LinkBasisSettings { rank_tolerance: 0.5, ..Default::default() };
    assert!(bad.validate().unwrap_err().to_string().contains("rank_tolerance"));
}

/// The paper basis as link fields: both field sets orthonormal and the modes' `Φ1`, `Φ2`
/// re-expanded on them to round-off (what makes the reduction exact).
#[test]
fn paper_basis_is_orthonormal_and_reexpanded_exactly() {
    let mx = |m: &Mat<f64>| {
        (0..m.nrows())
            .flat_map(|i| (0..m.ncols()).map(move |j| (i, j)))
            .fold(0.0f64, |a, (i, j)| a.max(m[(i, j)].abs()))
    };
    for spatial in [false, true] {
        let (sample, modes) = paper_sample(spatial);
        let settings = LinkBasisSettings { rigid_links: false, ..LinkBasisSettings::default() };
        let el: Vec<usize> = (modes.n_rigid()..modes.n_modes()).collect();
        let phi2 = Mat::from_fn(modes.phi2().nrows(), el.len(), |i, j| modes.phi2()[(i, el[j])]);
        let basis = LinkBasis::from_fields_and_forces(
            &sample.model,
            &[modes.phi1()],
            Some(phi2.as_ref()),
            &settings,
        )
        .unwrap();
        let (na, nb) = (basis.n1(), basis.n2());
        let o1 = basis.phi1.transpose() * &basis.b1 * &basis.phi1 - Mat::<f64>::identity(na, na);
        let o2 = basis.phi2.transpose() * &basis.b2 * &basis.phi2 - Mat::<f64>::identity(nb, nb);
        let r1 = &basis.phi1 * basis.coordinates1(modes.phi1()) - modes.phi1();
        let r2 = &basis.phi2 * basis.coordinates2(phi2.as_ref()) - &phi2;
        let (s1, s2) = (mx(&modes.phi1().to_owned()), mx(&phi2));
        eprintln!(
            "spatial {spatial}: |ΦᵀBΦ − I| {:.1e} / {:.1e}, re-expansion {:.1e} / {:.1e}",
            mx(&o1),
            mx(&o2),
            mx(&r1) / s1,
            mx(&r2) / s2
        );
        // measured ≤ 4.4e-16 and ≤ 1e-15 (relative), 2D and 3D
        assert!(mx(&o1) <= 1e-13 && mx(&o2) <= 1e-13);
        assert!(mx(&r1) <= 1e-13 * s1 && mx(&r2) <= 1e-13 * s2);
    }
}
