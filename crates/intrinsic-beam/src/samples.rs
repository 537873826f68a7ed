//! Canonical single-beam problems with provenance and known answers, shared by tests,
//! benches, verification cases and the CLI.
//!
//! Units are consistent and nondimensional: `L = 1`, bending stiffness `EI = 1`, mass per
//! length `m = 1` unless stated.

pub mod random;

use nalgebra::{Matrix6, Vector6};

use crate::beam::Beam;
use crate::components::Components;
use crate::error::Result;
use crate::kinematics::Kinematics;
use crate::loads::{Amplitude, LoadFrame, Loads, PointLoad};
use crate::mesh::Mesh;
use crate::problem::{BeamProblem, EndCondition};
use crate::section::Section;

/// Large-deflection cantilever under a dead tip load with `P L²/EI = 1` (the elastica):
/// tip displacement `(u_x, u_z)/L = (−0.05643, 0.30172)` and tip rotation `0.46135` rad
/// (Bisshopp & Drucker, *Q. Appl. Math.* 3 (1945); tabulated in Mattiasson, *IJNME* 17
/// (1981), Table 1, for `PL²/EI = 1`).
pub const ELASTICA_TIP_LOAD_1: (f64, f64, f64) = (-0.05643, 0.30172, 0.46135);

/// Exact tip displacement `(u_x, u_z)/L` of a cantilever rolled up by a follower tip moment to
/// end rotation `θ = M L/EI`: the arc of a circle, `(sin θ/θ − 1, (1 − cos θ)/θ)`.
pub fn roll_up_tip(theta: f64) -> (f64, f64) {
    if theta.abs() < 1e-12 {
        return (0.0, 0.0);
    }
    (theta.sin() / theta - 1.0, (1.0 - theta.cos()) / theta)
}

/// A slender isotropic beam section: `M = diag(m, m, m, j1, j2, j3)`,
/// `C⁻¹ = diag(EA, GA, GA, GJ, EI, EI)` with `m = 1`, `EI = 1`, `EA = GA = 1e4`, `GJ = 0.5`,
/// `j1 = 2e-4`, `j2 = j3 = 1e-4` (slenderness `L²·EA/EI = 1e4`: axial and shear strains
/// change static answers by ~1e-4 relative).
pub fn slender_section() -> Section {
    Section::from_diagonals([1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4], [1e4, 1e4, 1e4, 0.5, 1.0, 1.0])
        .expect("the slender section is valid")
}

/// An Euler–Bernoulli-like section for closed-form frequencies: rigid in shear (`f2, f3`),
/// massless in bending rotation (`ω2, ω3`), `m = 1`, `EA = 100`, `EI2 = 1`, `EI3 = 2`,
/// `GJ = 0.5`, torsional inertia `j1 = 0.01`. Axial wave speed 10, torsional √50.
pub fn euler_bernoulli_section() -> Section {
    Section::from_diagonals(
        [1.0, 1.0, 1.0, 0.01, 0.0, 0.0],
        [100.0, f64::INFINITY, f64::INFINITY, 0.5, 1.0, 2.0],
    )
    .expect("the Euler-Bernoulli section is valid")
}

/// A problem with its initial state and kinematics.
#[derive(Clone, Debug)]
pub struct Sample {
    /// Short name.
    pub name: &'static str,
    /// Where the setting and its known answer come from.
    pub provenance: &'static str,
    /// The problem.
    pub problem: BeamProblem,
    /// Initial beam vector.
    pub state: Vec<f64>,
    /// Initial kinematics.
    pub kinematics: Kinematics,
}

/// Cantilever (clamped at s = 0, free at s = L, along global e1) of the [`slender_section`],
/// released at rest from the arc left by a tip moment `M = EI θ0/L` with `θ0 = 1 rad`
/// (tip deflection `(1 − cos 1) L = 0.46 L`): uniform `m2 = −1`, positions rebuilt from strains.
/// Undamped, unloaded: the discrete energy `½ Σ h m2² C55 = 0.5` must be conserved.
pub fn cantilever_release(components: Components, n_elements: usize) -> Result<Sample> {
    let beam = Beam::new(slender_section(), Mesh::uniform(1.0, n_elements)?, components)?;
    let mut state = vec![0.0; beam.dim()];
    for e in 0..n_elements {
        beam.set_x2(&mut state, e, &Vector6::new(0.0, 0.0, 0.0, 0.0, -1.0, 0.0));
    }
    let kinematics = Kinematics::from_strains(
        &beam,
        &state,
        nalgebra::Vector4::new(1.0, 0.0, 0.0, 0.0),
        nalgebra::Vector3::zeros(),
    )?;
    let problem = BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())?;
    Ok(Sample {
        name: "cantilever-release",
        provenance: "released circular arc, theta0 = 1 rad; energy 0.5 exactly (theory.md §2)",
        problem,
        state,
        kinematics,
    })
}

/// Damping used to settle static samples: `D0 = −c M` (mass-proportional, all modes decay at
/// rate `c/2`) plus a small diffusive `D2 = d I` that removes mesh-scale oscillations.
pub fn settling_damping(section: &Section, c: f64, d: f64) -> Result<Section> {
    let d0 = -section.mass * c;
    section.clone().with_damping(d0, Matrix6::zeros(), Matrix6::identity() * d)
}

/// Cantilever of the [`slender_section`] with a dead tip load `P = 1` along global e3
/// (`PL²/EI = 1`), ramped over 2 s, settling under damping: the answer is
/// [`ELASTICA_TIP_LOAD_1`].
pub fn cantilever_dead_tip_load(components: Components, n_elements: usize) -> Result<Sample> {
    let section = settling_damping(&slender_section(), 4.0, 1e-3)?;
    let beam = Beam::new(section, Mesh::uniform(1.0, n_elements)?, components)?;
    let loads = Loads {
        point: vec![PointLoad {
            node: n_elements,
            frame: LoadFrame::Dead,
            value: Vector6::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0),
            amplitude: Amplitude::Ramp { duration: 2.0 },
        }],
        distributed: vec![],
    };
    let state = vec![0.0; beam.dim()];
    let kinematics = Kinematics::straight(&beam);
    let problem = BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, loads)?;
    Ok(Sample {
        name: "cantilever-dead-tip-load",
        provenance: "elastica, PL^2/EI = 1 (Bisshopp & Drucker 1945; Mattiasson 1981)",
        problem,
        state,
        kinematics,
    })
}

/// Cantilever of the [`slender_section`] rolled up by a follower tip moment about −e2 of
/// final value `θ_final EI/L`, applied in `stages` equal increments, each ramped over 1 s and
/// held for `hold` s (times in [`roll_up_schedule`]); the static answer at each stage is the
/// circle [`roll_up_tip`].
pub fn cantilever_follower_moment(
    components: Components,
    n_elements: usize,
    theta_final: f64,
    stages: usize,
    hold: f64,
) -> Result<Sample> {
    let section = settling_damping(&slender_section(), 4.0, 1e-3)?;
    let beam = Beam::new(section, Mesh::uniform(1.0, n_elements)?, components)?;
    let mut table = vec![(0.0, 0.0)];
    for (i, t_end) in roll_up_schedule(stages, hold).into_iter().enumerate() {
        let level = (i + 1) as f64 / stages as f64;
        table.push((t_end - hold, level));
        table.push((t_end, level));
    }
    let right = EndCondition::Force {
        value: Vector6::new(0.0, 0.0, 0.0, 0.0, -theta_final, 0.0),
        amplitude: Amplitude::Table(table),
    };
    let state = vec![0.0; beam.dim()];
    let kinematics = Kinematics::straight(&beam);
    let problem = BeamProblem::new(beam, EndCondition::Clamped, right, Loads::none())?;
    Ok(Sample {
        name: "cantilever-follower-moment",
        provenance: "pure bending: exact circle of curvature M/EI",
        problem,
        state,
        kinematics,
    })
}

/// End times of the hold phases of [`cantilever_follower_moment`] (stage `i` ramps during
/// `[i(1 + hold), i(1 + hold) + 1]` and holds until the returned time).
pub fn roll_up_schedule(stages: usize, hold: f64) -> Vec<f64> {
    (1..=stages).map(|i| i as f64 * (1.0 + hold)).collect()
}

/// Cantilever of the [`slender_section`] swinging from the straight, unstrained configuration
/// with a smooth, shear-free initial velocity `v3(s) = V (s/L)²`, `ω2 = −∂s v3`, `V = 2`:
/// a smooth solution for order and cross-checks (time vs space positions, RK4 vs midpoint).
pub fn cantilever_swing(components: Components, n_elements: usize) -> Result<Sample> {
    cantilever_swing_with(slender_section(), components, n_elements)
}

/// A moderately stiff section (`EA = GA = 100`, `EI = 1`, `GJ = 0.5`, `m = 1`, rotary
/// inertias `0.02, 0.01, 0.01`): highest mesh frequencies stay within explicit RK4's reach.
pub fn soft_section() -> Section {
    Section::from_diagonals([1.0, 1.0, 1.0, 0.02, 0.01, 0.01], [100.0, 100.0, 100.0, 0.5, 1.0, 1.0])
        .expect("the soft section is valid")
}

/// [`cantilever_swing`] with any section.
pub fn cantilever_swing_with(
    section: Section,
    components: Components,
    n_elements: usize,
) -> Result<Sample> {
    let beam = Beam::new(section, Mesh::uniform(1.0, n_elements)?, components)?;
    let mut state = vec![0.0; beam.dim()];
    for (node, s) in beam.mesh().nodes().to_vec().into_iter().enumerate() {
        // shear-free: ω2 = −∂s v3, so the stiff shear–rotation mode is not excited
        beam.set_x1(&mut state, node, &Vector6::new(0.0, 0.0, 2.0 * s * s, 0.0, -4.0 * s, 0.0));
    }
    let kinematics = Kinematics::straight(&beam);
    let problem = BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())?;
    Ok(Sample {
        name: "cantilever-swing",
        provenance: "smooth initial velocity field, no closed form (used for self-convergence)",
        problem,
        state,
        kinematics,
    })
}
