//! The structure studies of the verification crate on the settings of their verification
//! cases.

use flexmpc_verification::multibody::studies::{frame_invariance, hanging_hinge_reaction};

/// A beam hanging from a hinge (about e2) under gravity settles (strong diffusive damping) to
/// a hinge reaction equal to its weight `m g L`, upwards. At rest the node rows sum to
/// `x2_R − x2_L + Σ w_n m g = 0` exactly, so only the decay of the transient limits the match.
#[test]
fn hanging_beam_hinge_reaction_is_its_weight() {
    // 8 elements, D2 = 5 I, 6 s at dt = 2 ms (the study of the verification case).
    let (vertical, horizontal, axis_moment) = hanging_hinge_reaction(8, 5.0, 6.0).unwrap();
    assert!(vertical.abs() < 1e-6, "vertical reaction / weight − 1 = {vertical}");
    assert!(horizontal < 1e-6, "horizontal reaction / weight = {horizontal}");
    // The hinge carries no moment about its axis.
    assert!(axis_moment < 1e-12, "moment about the hinge axis {axis_moment}");
}

/// Rotating a structure, its gravity and its global hinge axes rigidly leaves the intrinsic
/// states unchanged (they are local-frame quantities) and rotates the positions (the study of
/// the verification case `multibody-constraints/frame-invariance`, 200 steps).
#[test]
fn frame_invariance_of_the_ball_joint_structure() {
    let (states, positions) = frame_invariance(200).unwrap();
    assert!(states < 1e-12, "intrinsic states differ by {states} of their scale");
    assert!(positions < 1e-11, "positions differ by {positions} m after rotating back");
}
