//! The planar evaluation against the general one at random planar states (joint angles past
//! 90°, unnormalised quaternions, non-zero rates, forces and inputs).

use crate::basis::ModeSelection;
use crate::exact_joints::{from_fields, paper_reduction, ExactJointsRom};
use crate::samples::{self, paper_2d_selection};
use crate::{BasisSettings, LinkBasisSettings, RomOptions, StructureModel};
use intrinsic_beam::Section;
use proptest::prelude::*;
use std::sync::OnceLock;

/// The 2D two-link on `n` elements per link: link fields from the constrained modes (rigid +
/// `elastic`) at `angles` plus rigid link motions.
fn per_link(n: usize, damped: bool, angles: &[f64], elastic: usize) -> ExactJointsRom {
    let section = if damped { Section::paper_2d() } else { Section::paper_2d().undamped() };
    let build = |a: f64| multibody_constraints::samples::paper_2d(section.clone(), n, a).unwrap();
    let structure = build(0.0);
    let model = StructureModel::new(&structure).unwrap();
    let mut fields = Vec::new();
    for &a in angles {
        let m = StructureModel::new(&build(a)).unwrap();
        let b = m.modes(&BasisSettings::default()).unwrap();
        fields.push(
            b.select(&ModeSelection::Lowest(b.n_rigid() + elastic)).unwrap().phi1().to_owned(),
        );
    }
    let refs: Vec<_> = fields.iter().map(|f| f.as_ref()).collect();
    let inputs = samples::inputs_2d(&structure, &model).unwrap();
    let damping = damped.then_some(&model.damping);
    from_fields(&structure, &model, &refs, &LinkBasisSettings::default(), damping, &inputs).unwrap()
}

/// The paper's damped 2D two-link on 8 elements per link on the paper's basis.
fn paper() -> ExactJointsRom {
    let opts = RomOptions { quaternions: false, ..RomOptions::default() };
    let selection = paper_2d_selection();
    let s = samples::paper_2d(8, 0.0, true, &selection, &opts).unwrap();
    let modes = s.basis.select(&selection).unwrap();
    let inputs = samples::inputs_2d(&s.structure, &s.model).unwrap();
    paper_reduction(&s.structure, &s.model, &modes, Some(&s.model.damping), &inputs).unwrap()
}

fn models() -> &'static [ExactJointsRom; 3] {
    static M: OnceLock<[ExactJointsRom; 3]> = OnceLock::new();
    M.get_or_init(|| {
        [per_link(6, true, &[0.0], 4), per_link(6, false, &[0.0, 0.8, 1.6], 3), paper()]
    })
}

/// A planar state: `p`, `p2` from `seed` at `scale`, the joint turned by `angle` about the
/// normal with norm `norm`, the root turned by `root`.
fn planar_state(
    rom: &ExactJointsRom,
    seed: f64,
    scale: f64,
    angle: f64,
    norm: f64,
    root: f64,
) -> Vec<f64> {
    let pl = rom.planar.as_deref().unwrap();
    let mut x = rom.reference_state();
    for (i, v) in x[..rom.n_p() + rom.n_p2()].iter_mut().enumerate() {
        *v = scale * (seed * (i as f64 + 1.3)).sin();
    }
    let turn = |x: &mut [f64], o: usize, t: f64, s: f64| {
        let (a, b) = (x[o], x[o + pl.nu]);
        let (c, sn) = ((0.5 * t).cos(), (0.5 * t).sin());
        x[o] = s * (a * c - b * sn);
        x[o + pl.nu] = s * (a * sn + b * c);
    };
    for j in 0..rom.n_joints() {
        turn(&mut x, rom.joint_offset(j), angle, norm);
    }
    if rom.has_root() {
        turn(&mut x, rom.root_offset(), root, 1.0);
    }
    x
}

fn rel(a: &[f64], b: &[f64]) -> f64 {
    let big = b.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(f64::MIN_POSITIVE);
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / big
}

#[test]
fn two_d_models_are_planar_and_three_d_are_not() {
    assert!(models().iter().all(|m| m.is_planar()));
    let opts = RomOptions { quaternions: false, ..RomOptions::default() };
    let sel = ModeSelection::Lowest(4);
    let s = samples::paper_3d(2, 0.0, false, &sel, &opts).unwrap();
    let m = s.model.modes(&BasisSettings::default()).unwrap();
    let modes = m.select(&ModeSelection::Lowest(m.n_rigid() + 2)).unwrap();
    let rom = from_fields(
        &s.structure,
        &s.model,
        &[modes.phi1()],
        &LinkBasisSettings::default(),
        None,
        &[],
    )
    .unwrap();
    assert!(!rom.is_planar());
}

/// A joint quaternion with an out-of-plane component takes the general path (same result).
#[test]
fn out_of_plane_states_take_the_general_path() {
    let rom = &models()[0];
    let mut x = planar_state(rom, 0.7, 0.5, 1.9, 1.0, 0.3);
    let o = rom.joint_offset(0);
    let c = (1..4).find(|&c| c != rom.planar.as_deref().unwrap().nu).unwrap();
    x[o + c] = 1e-3;
    let u = vec![0.3; rom.n_inputs()];
    let mut f = vec![0.0; rom.n_state()];
    assert!(rom.planar_eval(&x, &u, &mut f, None).is_none());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// rhs, ∂f/∂x and ∂f/∂u of the planar evaluation equal the general evaluation's to 1e-12
    /// of the largest entry.
    #[test]
    fn planar_evaluation_equals_the_general_one(
        which in 0usize..3,
        seed in 0.1f64..10.0,
        scale in 0.01f64..3.0,
        angle in -2.6f64..2.6,
        norm in 0.9f64..1.1,
        root in -3.1f64..3.1,
        us in -2.0f64..2.0,
    ) {
        let rom = &models()[which];
        let x = planar_state(rom, seed, scale, angle, norm, root);
        let (n, nu) = (rom.n_state(), rom.n_inputs());
        let u: Vec<f64> = (0..nu).map(|i| us * (1.0 + 0.3 * i as f64)).collect();
        let (mut f0, mut j0, mut u0) = (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]);
        let (mut f1, mut j1, mut u1) = (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]);
        let pl = rom.planar.as_deref().unwrap();
        prop_assert!(pl.accepts(&x, pl.offsets.iter().copied()), "the state is planar");
        rom.eval_general(&x, &u, &mut f0, Some((&mut j0, &mut u0))).unwrap();
        rom.rhs_and_jacobian(&x, &u, &mut f1, &mut j1, &mut u1).unwrap();
        let mut fr = vec![0.0; n];
        rom.rhs(&x, &u, &mut fr).unwrap();
        let (ef, ej, eu, er) = (rel(&f1, &f0), rel(&j1, &j0), rel(&u1, &u0), rel(&fr, &f0));
        prop_assert!(ef <= 1e-12 && ej <= 1e-12 && eu <= 1e-12 && er <= 1e-12,
            "model {which}: rhs {ef:e}, ∂f/∂x {ej:e}, ∂f/∂u {eu:e}, rhs alone {er:e}");
    }
}

/// Toward ±π `S` of theory.md §10.4 approaches singularity: there both evaluations carry
/// round-off amplified by the same conditioning, and their difference stays of the size of the
/// general evaluation's own change when the joint angle moves by a relative 1e-15.
#[test]
fn near_the_range_limit_the_difference_is_round_off() {
    let (n, rom) = (models()[0].n_state(), &models()[0]);
    let nu = rom.n_inputs();
    let u = vec![0.2; nu];
    let run = |x: &[f64], planar: bool| {
        let (mut f, mut j, mut ju) = (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]);
        if planar {
            rom.rhs_and_jacobian(x, &u, &mut f, &mut j, &mut ju).unwrap();
        } else {
            rom.eval_general(x, &u, &mut f, Some((&mut j, &mut ju))).unwrap();
        }
        f.extend(j);
        f
    };
    for angle in [2.8, -2.9, 3.0] {
        for norm in [0.8, 1.0, 1.2] {
            let x = planar_state(rom, 0.1, 2.4, angle, norm, 0.4);
            let xp = planar_state(rom, 0.1, 2.4, angle * (1.0 + 1e-15), norm, 0.4);
            let (g, p, gp) = (run(&x, false), run(&x, true), run(&xp, false));
            let (diff, sens) = (rel(&p, &g), rel(&gp, &g));
            assert!(
                diff <= (100.0 * sens).max(1e-12),
                "angle {angle}, norm {norm}: difference {diff:e}, sensitivity {sens:e}"
            );
        }
    }
}
