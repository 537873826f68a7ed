//! Study (a), FE mesh against frequency error and time: the clamped–free cantilever
//! (`L = EI = m = 1`, Euler–Bernoulli section) against the closed-form first bending frequency,
//! by the dense single-beam route (the verification crate's oracle, `beam::dense_modes`) and by modal-rom's constrained SVD route; the
//! cost of an implicit-midpoint step of the same mesh (slender cantilever released from a
//! 1 rad arc); and the paper's 2D two-link (first five elastic modes).

use intrinsic_beam::closed_form::{bending, Supports};
use intrinsic_beam::samples;
use intrinsic_beam::{
    Beam, BeamProblem, Components, EndCondition, ImplicitMidpoint, Loads, Mesh, NewtonSettings,
    Section,
};
use modal_rom::{BasisSettings, StructureModel};
use multibody_constraints::{
    End, EndRef, JointKind, Placement, Structure, StructureBeam, StructureSettings, Support,
};

use super::{timed, Error, Result};
use crate::beam::dense_modes::{family, linear_modes, Family};

/// Closed-form first bending frequency of the cantilever (rad/s).
pub fn exact_omega1() -> f64 {
    bending(Supports::ClampedFree, 1.0, 1.0, 1.0, 1)[0]
}

fn cantilever_structure(n: usize) -> Result<Structure> {
    let beam =
        Beam::new(samples::euler_bernoulli_section(), Mesh::uniform(1.0, n)?, Components::Planar)?;
    Ok(Structure::new(
        vec![StructureBeam::new("beam", beam, Placement::origin())],
        vec![],
        vec![Support {
            name: "clamp".into(),
            end: EndRef::new("beam", End::Start),
            kind: JointKind::Weld,
        }],
        StructureSettings::default(),
    )?)
}

/// First bending frequency by the dense single-beam route (`beam::dense_modes`).
pub fn dense_omega1(n: usize) -> Result<f64> {
    let beam =
        Beam::new(samples::euler_bernoulli_section(), Mesh::uniform(1.0, n)?, Components::Planar)?;
    let problem = BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())?;
    let modes = linear_modes(&problem)?;
    modes
        .iter()
        .find(|m| m.omega > 1e-3 && family(&problem.beam, m) == Family::BendingE2)
        .map(|m| m.omega)
        .ok_or_else(|| Error::from(format!("no bending mode at {n} elements")))
}

/// First elastic frequency (the first bending mode: axial and shear lie far above) and its
/// label by modal-rom (structure operators + constrained modes).
pub fn rom_omega1(n: usize) -> Result<(f64, String)> {
    let s = cantilever_structure(n)?;
    let basis = StructureModel::new(&s)?.modes(&BasisSettings::default())?;
    let j = basis.n_rigid();
    if j >= basis.n_modes() {
        return Err(Error::from(format!("no elastic mode at {n} elements (modal-rom)")));
    }
    Ok((basis.omega()[j], basis.labels()[j].clone()))
}

/// First five elastic frequencies of the paper's 2D two-link at 0° with `n` elements per link.
pub fn two_link(n: usize) -> Result<Vec<f64>> {
    let s = multibody_constraints::samples::paper_2d(Section::paper_2d(), n, 0.0)?;
    let basis = StructureModel::new(&s)?.modes(&BasisSettings::default())?;
    let r = basis.n_rigid();
    Ok(basis.omega()[r..(r + 5).min(basis.n_modes())].to_vec())
}

/// Median µs per implicit-midpoint step and Newton iterations per step, cantilever release.
pub fn step_cost(n: usize, steps: usize, k: usize) -> Result<(f64, f64)> {
    let s = samples::cantilever_release(Components::Planar, n)?;
    let mut sim =
        ImplicitMidpoint::new(s.problem, s.state, s.kinematics, NewtonSettings::default())?;
    for _ in 0..10 {
        sim.step(1e-3)?;
    }
    let c0 = sim.counters().newton_iterations;
    let mut runs = 0;
    let (_, t) = timed(k, 5.0, || -> Result<()> {
        runs += 1;
        for _ in 0..steps {
            sim.step(1e-3)?;
        }
        Ok(())
    })?;
    let its = (sim.counters().newton_iterations - c0) as f64 / (runs * steps) as f64;
    Ok((t / steps as f64 * 1e6, its))
}
