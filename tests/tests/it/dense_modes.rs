//! The dense single-beam modes oracle (`beam::dense_modes`): graded meshes keep second order,
//! and modal-rom's constrained route agrees with it on the Euler–Bernoulli section (rigid shear,
//! massless rotation) to round-off.

use flexmpc_verification::beam::dense_modes::{family, linear_modes, Family};
use intrinsic_beam::closed_form::{bending, Supports};
use intrinsic_beam::{samples, Beam, BeamProblem, Components, EndCondition, Loads, Mesh};
use modal_rom::{BasisSettings, ModeKind, StructureModel};
use multibody_constraints::{End, EndRef, JointKind, Support};
use multibody_constraints::{Placement, Structure, StructureBeam, StructureSettings};

/// The first bending frequency of a graded mesh converges to the closed form at second order.
#[test]
fn graded_meshes_converge_at_second_order() {
    let exact = bending(Supports::ClampedFree, 1.0, 1.0, 1.0, 1)[0];
    let mut errors = Vec::new();
    for n in [16, 32, 64] {
        let beam = Beam::new(
            samples::euler_bernoulli_section(),
            Mesh::graded(1.0, n, 3.0).unwrap(),
            Components::Planar,
        )
        .unwrap();
        let problem =
            BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())
                .unwrap();
        let modes = linear_modes(&problem).unwrap();
        let omega = modes.iter().find(|m| m.omega > 1.0).unwrap().omega;
        errors.push((omega - exact).abs() / exact);
    }
    // smoothly graded meshes keep second order (ratio ≈ 4 per doubling)
    assert!(errors[0] / errors[1] > 3.5 && errors[1] / errors[2] > 3.5, "{errors:?}");
}

/// The lowest `count` bending frequencies of the dense single-beam route.
fn dense_bending(n: usize, left: EndCondition, count: usize) -> Vec<f64> {
    let beam = Beam::new(
        samples::euler_bernoulli_section(),
        Mesh::uniform(1.0, n).unwrap(),
        Components::Planar,
    )
    .unwrap();
    let p = BeamProblem::new(beam, left, EndCondition::Free, Loads::none()).unwrap();
    linear_modes(&p)
        .unwrap()
        .iter()
        .filter(|m| m.omega > 1e-3 && family(&p.beam, m) == Family::BendingE2)
        .map(|m| m.omega)
        .take(count)
        .collect()
}

/// The lowest `count` bending frequencies of modal-rom's constrained route: one planar beam
/// with `support` at `s = 0`.
fn constrained_bending(n: usize, support: JointKind, count: usize) -> Vec<f64> {
    let beam = Beam::new(
        samples::euler_bernoulli_section(),
        Mesh::uniform(1.0, n).unwrap(),
        Components::Planar,
    )
    .unwrap();
    let structure = Structure::new(
        vec![StructureBeam::new("beam", beam, Placement::origin())],
        vec![],
        vec![Support { name: "root".into(), end: EndRef::new("beam", End::Start), kind: support }],
        StructureSettings::default(),
    )
    .unwrap();
    let b = StructureModel::new(&structure).unwrap().modes(&BasisSettings::default()).unwrap();
    (0..b.n_modes())
        .filter(|&j| b.kinds()[j] == ModeKind::BendingE2)
        .map(|j| b.omega()[j])
        .take(count)
        .collect()
}

/// Round-off bound of the SVD route for the lowest modes: `ε ω_max / ω` with
/// `ω_max ≈ 4.8 N³` and `ω ≥ 3.5`: `≈ 1.3e-9` at 200 elements; 1e-8 leaves a margin of ~8.
const ROUND_OFF: f64 = 1e-8;

/// Clamped (10–200 elements, three modes) and pinned (12–130 elements, two modes): the two
/// routes agree to round-off.
#[test]
fn constrained_route_matches_the_dense_oracle() {
    for (support, end, meshes, count) in [
        (JointKind::Weld, EndCondition::Clamped, &[10usize, 20, 50, 100, 200][..], 3),
        (JointKind::Ball, EndCondition::Pinned, &[12, 45, 64, 130][..], 2),
    ] {
        for &n in meshes {
            let w = constrained_bending(n, support.clone(), count);
            let d = dense_bending(n, end.clone(), count);
            for k in 0..count {
                let r = w[k] / d[k] - 1.0;
                assert!(r.abs() < ROUND_OFF, "{end:?} {n} elements, mode {k}: {r:e}");
            }
        }
    }
}
