//! Verification cases of the `multibody-constraints` crate (names `multibody-constraints/<case>`).
//!
//! Each case runs one of the [`studies`]; tolerances follow from the Newton
//! tolerance (1e-12 relative update), round-off on O(1) direction cosines, and the O(h²)
//! convergence of the lumped-mass links.

pub mod studies;

use crate::{Case, CaseOutcome, Metric, Tier};

/// The cases of `multibody-constraints`.
pub fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "multibody-constraints/two-link-energy",
            tier: Tier::Quick,
            run: two_link_energy,
        },
        Case {
            name: "multibody-constraints/two-link-energy-fine",
            tier: Tier::Full,
            run: two_link_energy_fine,
        },
        Case { name: "multibody-constraints/joint-gap", tier: Tier::Quick, run: joint_gap },
        Case {
            name: "multibody-constraints/stiff-double-pendulum",
            tier: Tier::Full,
            run: stiff_pendulum,
        },
        Case {
            name: "multibody-constraints/stiff-double-pendulum-order",
            tier: Tier::Quick,
            run: stiff_pendulum_order,
        },
        Case {
            name: "multibody-constraints/hinge-reaction",
            tier: Tier::Quick,
            run: hinge_reaction,
        },
        Case {
            name: "multibody-constraints/ball-joint-balance",
            tier: Tier::Quick,
            run: ball_joint,
        },
        Case {
            name: "multibody-constraints/frame-invariance",
            tier: Tier::Quick,
            run: frame_invariance,
        },
        Case { name: "multibody-constraints/l-frame", tier: Tier::Quick, run: l_frame },
        Case { name: "multibody-constraints/null-space", tier: Tier::Quick, run: null_space },
        Case { name: "multibody-constraints/bad-topology", tier: Tier::Quick, run: bad_topology },
    ]
}

fn swing_metrics(n: usize, dt: f64, steps: usize) -> CaseOutcome {
    let s = studies::two_link_swing(n, dt, steps, 4.0).map_err(|e| e.to_string())?;
    Ok(vec![
        // 10⁴ steps, each solved to a 1e-12 relative update: drift stays far below 1e-10.
        Metric::at_most(
            format!("relative energy drift, 2x{n} elements, {steps} steps"),
            s.energy_drift,
            1e-10,
        ),
        Metric::at_least("max |elbow angle| (deg)", s.max_elbow_angle.to_degrees(), 60.0),
        // Compatibility rows are solved with the step: round-off times velocity scale (~4).
        Metric::at_most(
            "max velocity-constraint violation at midpoints",
            s.velocity_violation,
            1e-10,
        ),
        Metric::at_most("max balance violation at midpoints", s.balance_violation, 1e-8),
        Metric::at_most("max elbow gap (m)", s.max_gap, 1e-12),
    ])
}

fn two_link_energy() -> CaseOutcome {
    swing_metrics(20, 1e-3, 10_000)
}

fn two_link_energy_fine() -> CaseOutcome {
    swing_metrics(50, 1e-3, 10_000)
}

/// The position gap between joined ends: with one midpoint rotation per end for both the
/// joint rows and `r⁺ = r + dt T_mid v_mid`, the increments of joined ends are equal to
/// solver tolerance, so the gap stays at round-off for every step; the reported bound
/// `1e-6 (dt / 1e-3)²` (an O(dt²) drift allowance) shrinks with the step.
fn joint_gap() -> CaseOutcome {
    let mut out = Vec::new();
    for dt in [4e-3, 2e-3, 1e-3] {
        let steps = (2.0 / dt) as usize;
        let s = studies::two_link_swing(10, dt, steps, 4.0).map_err(|e| e.to_string())?;
        let bound = 1e-6 * (dt / 1e-3) * (dt / 1e-3);
        out.push(Metric::at_most(format!("max elbow gap over 2 s, dt = {dt}"), s.max_gap, bound));
    }
    Ok(out)
}

fn stiff_pendulum() -> CaseOutcome {
    let mut out = Vec::new();
    for (t1, t2) in [(30f64, 0f64), (0.0, 30.0)] {
        let e =
            studies::stiff_pendulum_error(100, 1e-3, 5.0, 1e6, t1.to_radians(), t2.to_radians())
                .map_err(|e| e.to_string())?;
        out.push(Metric::at_most(
            format!(
                "max angle error (rad) vs rigid rods, released at {t1}°/{t2}°, 2x100 elements, 5 s"
            ),
            e,
            1e-3,
        ));
    }
    Ok(out)
}

/// The lumped node masses give the links' inertia with O(h²) error, so the angle error
/// against the rigid rods falls as 1/N²; Richardson's estimate of the limit is tiny.
fn stiff_pendulum_order() -> CaseOutcome {
    let (t1, t2) = (30f64.to_radians(), 0.0);
    let e1 =
        studies::stiff_pendulum_error(10, 1e-3, 5.0, 1e6, t1, t2).map_err(|e| e.to_string())?;
    let e2 =
        studies::stiff_pendulum_error(20, 1e-3, 5.0, 1e6, t1, t2).map_err(|e| e.to_string())?;
    Ok(vec![
        Metric::at_least("observed order of the angle error (2x10 → 2x20)", (e1 / e2).log2(), 1.9),
        Metric::at_most(
            "Richardson-extrapolated angle error (rad)",
            (e2 - (e1 - e2) / 3.0).abs(),
            1e-3,
        ),
    ])
}

fn hinge_reaction() -> CaseOutcome {
    let (vert, horiz, moment) =
        studies::hanging_hinge_reaction(8, 5.0, 6.0).map_err(|e| e.to_string())?;
    Ok(vec![
        // The transient decays like exp(−λ t) with strong damping; 1e-6 is reached by 6 s.
        Metric::at_most("|vertical hinge reaction / weight − 1|", vert.abs(), 1e-6),
        Metric::at_most("horizontal hinge reaction / weight", horiz, 1e-6),
        Metric::at_most("moment about the hinge axis", moment, 1e-12),
    ])
}

fn ball_joint() -> CaseOutcome {
    let (sum, moment, vv, scale) =
        studies::ball_joint_balance(6, 500).map_err(|e| e.to_string())?;
    Ok(vec![
        Metric::at_least("joint load scale (N)", scale, 1.0),
        // Balance (12) is a row of the Newton system: round-off on O(1) cosines.
        Metric::at_most("|Σ forces on the three ends| / load scale", sum, 1e-12),
        Metric::at_most("max |moment| at the ball joint / load scale", moment, 1e-12),
        Metric::at_most("max velocity-compatibility violation (11)", vv, 1e-11),
    ])
}

fn frame_invariance() -> CaseOutcome {
    let (ds, dp) = studies::frame_invariance(200).map_err(|e| e.to_string())?;
    Ok(vec![
        Metric::at_most("max intrinsic-state difference / state scale", ds, 1e-12),
        Metric::at_most("max position difference after rotating back (m)", dp, 1e-11),
    ])
}

fn l_frame() -> CaseOutcome {
    let (series, drift) = studies::l_frame(8, 5e-3, 5.0, 0.2, true).map_err(|e| e.to_string())?;
    let zmax = series.iter().map(|s| s.2.abs()).fold(0.0, f64::max);
    Ok(vec![
        Metric::at_least("max out-of-plane tip displacement (m)", zmax, 0.05),
        Metric::at_most("drift of ε − F·r_elbow / (F max z)", drift, 1e-10),
    ])
}

fn null_space() -> CaseOutcome {
    let mut out = Vec::new();
    for deg in [0.0f64, 45.0, 90.0] {
        let (gz, orth, _) =
            studies::null_space_quality(50, deg.to_radians()).map_err(|e| e.to_string())?;
        out.push(Metric::at_most(format!("max |G Z| at {deg}°"), gz, 1e-13));
        out.push(Metric::at_most(format!("max |ZᵀZ − I| at {deg}°"), orth, 1e-13));
    }
    Ok(out)
}

fn bad_topology() -> CaseOutcome {
    let (rejected, tried) = studies::topology_errors();
    Ok(vec![Metric::at_least(
        format!("bad topologies rejected with the right error (of {tried})"),
        rejected as f64,
        tried as f64,
    )])
}
