//! The single-beam studies of the verification crate on cheap settings (the
//! `cargo xtask verify intrinsic-beam/` cases run the same studies, some with finer settings).

use flexmpc_verification::beam::dense_modes::Family;
use flexmpc_verification::beam::studies::*;
use intrinsic_beam::closed_form::Supports;
use intrinsic_beam::samples::ELASTICA_TIP_LOAD_1;
use intrinsic_beam::Components;

/// Identities hold to round-off on random data.
#[test]
fn section2_identities_hold_on_random_sections() {
    let worst = identity_residuals(200, 7).unwrap();
    // relative round-off of sums of O(10–100) products
    assert!(worst.iter().all(|&w| w < 1e-13), "{worst:?}");
}

/// Energy drift below 1e-10 over 10⁴ steps from a large-amplitude state.
#[test]
fn energy_is_conserved_over_ten_thousand_steps() {
    let study = energy_conservation(Components::Planar, 10, 1e-3, 10_000).unwrap();
    assert!(study.max_tip_deflection > 0.3, "amplitude {}", study.max_tip_deflection);
    // solver tolerance 1e-12 per step, errors of random sign: ~1e-14 expected
    assert!(study.max_relative_drift < 1e-10, "drift {:e}", study.max_relative_drift);
}

/// With D2 > 0 the energy falls monotonically, by exactly the dissipated work.
#[test]
fn damped_energy_falls_monotonically() {
    let study = damped_decay(Components::Planar, 10, 1e-3, 1e-3, 2000).unwrap();
    // each step: Δε = dt·P_damping ≤ 0 up to solver tolerance (1e-12 relative updates)
    assert!(study.max_relative_increase <= 1e-13, "{study:?}");
    assert!(study.final_over_initial < 0.9, "{study:?}");
    assert!(study.max_balance_error < 1e-12, "{study:?}");
}

/// Second-order convergence of linear frequencies to closed-form beam theory.
#[test]
fn frequencies_converge_at_second_order() {
    for supports in [Supports::ClampedFree, Supports::PinnedFree, Supports::FreeFree] {
        for fam in [Family::Axial, Family::BendingE2, Family::Torsion, Family::BendingE3] {
            let rows = frequency_convergence(supports, fam, &[8, 16, 32]).unwrap();
            let order = observed_order(&rows);
            // the staggered scheme with lumped weights is second order; allow ±0.1 for the
            // pre-asymptotic range at 16–32 elements
            assert!((order - 2.0).abs() < 0.1, "{supports:?} {fam:?}: order {order}, {rows:?}");
            // leading error term c (ωh)² with c ≤ ~0.1 for the first mode at h = 1/32
            assert!(rows[2].relative_error < 5e-3, "{supports:?} {fam:?}: {rows:?}");
        }
    }
}

/// The elastica under a dead tip load, PL²/EI = 1, within 0.5%.
#[test]
fn dead_tip_load_matches_the_elastica() {
    let (ux, uz, rot) = dead_tip_load(Components::Planar, 20, 0.01, 8.0).unwrap();
    let (ex, ez, er) = ELASTICA_TIP_LOAD_1;
    for (got, want) in [(ux, ex), (uz, ez), (rot, er)] {
        assert!(((got - want) / want).abs() < 5e-3, "{got} vs {want}");
    }
}

/// A follower tip moment rolls the cantilever up to the exact circle up to θ = 2π.
#[test]
fn follower_moment_rolls_up_to_the_circle() {
    let rows = roll_up(Components::Planar, 40, 4, 3.0, 0.01).unwrap();
    assert!((rows[3].theta - 2.0 * std::f64::consts::PI).abs() < 1e-12);
    for r in &rows {
        // midpoint chords of an arc: position error ≲ θ² (h/L)²/24 · L ≈ 1e-3 at θ = 2π,
        // N = 40, plus the settling residue
        assert!(r.error < 2.5e-3, "{r:?}");
    }
}

/// Positions integrated in time agree with positions rebuilt from strains; the gap
/// shrinks with the mesh (second order) and with the step.
#[test]
fn time_and_space_positions_agree() {
    let mesh: Vec<f64> = [10, 20, 40]
        .iter()
        .map(|&n| time_space_gap(Components::Planar, n, 2.5e-3, 0.5).unwrap())
        .collect();
    assert!(mesh[0] < 2e-4, "{mesh:?}");
    assert!(mesh[0] / mesh[1] > 3.0 && mesh[1] / mesh[2] > 3.0, "{mesh:?}");
    let step: Vec<f64> = [2e-2, 1e-2, 5e-3]
        .iter()
        .map(|&dt| time_space_gap(Components::Planar, 80, dt, 0.5).unwrap())
        .collect();
    assert!(step[0] / step[1] > 3.0 && step[1] / step[2] > 3.0, "{step:?}");
}

/// A planar run reproduces the spatial run (out-of-plane directions stay zero).
#[test]
fn planar_and_spatial_runs_agree() {
    let (dx, dr) = planar_vs_spatial(10, 1e-3, 500).unwrap();
    // same arithmetic up to the order of operations in the sparse solves: round-off level
    assert!(dx < 1e-10 && dr < 1e-10, "{dx:e} {dr:e}");
}

/// Cross-check: implicit midpoint converges to RK4 at second order.
#[test]
fn midpoint_converges_to_rk4_at_second_order() {
    let e: Vec<f64> =
        [1e-3, 5e-4].iter().map(|&dt| midpoint_vs_rk4(10, dt, 1e-4, 0.2).unwrap()).collect();
    let order = (e[0] / e[1]).log2();
    assert!((order - 2.0).abs() < 0.1, "{e:?}");
}

/// The integrated kinematics of the spinning, loaded 3D two-link match the strains to the
/// spatial scheme's second order: the chord mismatch falls ≈ 4× per mesh halving and does not
/// change with the time step.
#[test]
fn kinematic_mismatch_is_second_order_in_the_mesh_and_not_the_step() {
    use flexmpc_verification::beam::compat::two_link_run;
    let t_end = 0.75;
    let coarse = two_link_run(8, 1e-3, t_end).unwrap().worst;
    let fine = two_link_run(16, 1e-3, t_end).unwrap().worst;
    let short_step = two_link_run(8, 5e-4, t_end).unwrap().worst;
    // measured: 1.87e-2, 5.78e-3 (ratio 3.2, 3.6 at 16→32); shear strains ≤ 1.7e-4; the
    // half step changes the mismatch by 5e-4 of itself
    assert!(coarse.chord < 2.0 / 64.0 && coarse.chord > 10.0 * coarse.shear, "{coarse:?}");
    assert!(coarse.chord / fine.chord > 2.8, "{coarse:?} {fine:?}");
    assert!((short_step.chord - coarse.chord).abs() < 1e-2 * coarse.chord, "{short_step:?}");
}
