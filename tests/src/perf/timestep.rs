//! Study (c), time step against error and time: the paper's 2D two-link spun at ω0 about the
//! root and kicked by a transverse follower tip force for the first 0.05 s, integrated by the
//! FE plant (implicit midpoint, `multibody-constraints`) and by the paper's reduced model
//! (2 rigid + 4 axial + 4 bending modes with quaternion modes, `mpc::Setup`) with the three
//! shooting integrators of `ocp-transcription` (implicit midpoint, RK4, Lawson RK4 on `W`);
//! errors against a tight reference of the same model.

use intrinsic_beam::{Amplitude, LoadFrame, PointLoad};
use mpc::{RomDynamics, Scenario, Setup};
use multibody_constraints::{Plant, PlantSettings};
use nalgebra::{Vector3, Vector6};
use ocp_transcription::{Integrator, IntegratorSettings};

pub use ocp_transcription::IntegratorKind;

use super::Result;

/// Elements per link.
pub const ELEMENTS: usize = 20;
/// Output (and control) interval: every step count divides it.
pub const INTERVAL: f64 = 0.05;
/// Initial rigid rotation rate about the root (rad/s).
pub const OMEGA0: f64 = 1.0;
/// Transverse follower tip force over the first interval (N).
pub const KICK: f64 = 0.05;

/// Tip positions at the ends of the output intervals.
pub type Tips = Vec<[f64; 3]>;

fn fe_tips(setup: &Setup, per_interval: usize, horizon: f64) -> Result<Tips> {
    let structure = &setup.scenario.structure;
    let dt = INTERVAL / per_interval as f64;
    let mut plant = Plant::new(structure.clone(), PlantSettings { dt, ..Default::default() })?;
    plant.set_state(
        &structure.rigid_rotation_state(Vector3::new(0.0, OMEGA0, 0.0), Vector3::zeros()),
    )?;
    plant.loads_mut(1).point.push(PointLoad {
        node: ELEMENTS,
        frame: LoadFrame::Follower,
        value: Vector6::new(0.0, 0.0, KICK, 0.0, 0.0, 0.0),
        amplitude: Amplitude::Constant,
    });
    let intervals = (horizon / INTERVAL).round() as usize;
    let mut tips = Vec::with_capacity(intervals);
    for i in 0..intervals {
        if i == 1 {
            plant.loads_mut(1).point.clear();
        }
        for _ in 0..per_interval {
            plant.step()?;
        }
        let r = plant.kinematics()[1].r[ELEMENTS];
        tips.push([r.x, r.y, r.z]);
    }
    Ok(tips)
}

/// The ROM trajectory's states at the ends of the output intervals.
fn rom_states(
    setup: &Setup,
    model: &RomDynamics,
    kind: IntegratorKind,
    substeps: usize,
    q0: &[f64],
    horizon: f64,
) -> Result<Vec<Vec<f64>>> {
    let mut integ = Integrator::new(model, &IntegratorSettings::new(kind, substeps), INTERVAL)?;
    let intervals = (horizon / INTERVAL).round() as usize;
    let nu = setup.rom.n_inputs();
    let mut x = q0.to_vec();
    let mut next = vec![0.0; x.len()];
    let mut out = Vec::with_capacity(intervals);
    for i in 0..intervals {
        let mut u = vec![0.0; nu];
        if i == 0 {
            u[nu - 1] = KICK; // "tip force e3", the last input of the paper's 2D scenario
        }
        integ.integrate(model, &x, &u, &mut next)?;
        if next.iter().any(|v| !v.is_finite() || v.abs() > 1e6) {
            return Err("unstable".into());
        }
        std::mem::swap(&mut x, &mut next);
        out.push(x.clone());
    }
    Ok(out)
}

fn rom_tips(setup: &Setup, states: &[Vec<f64>]) -> Result<Tips> {
    states.iter().map(|q| Ok(setup.rom.positions(q)?[1][ELEMENTS])).collect()
}

/// Max over output times of the tip error, relative to the reference's largest excursion.
pub fn tip_error(tips: &Tips, reference: &Tips, r0: [f64; 3]) -> f64 {
    let d = |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let scale = reference.iter().map(|r| d(r, &r0)).fold(0.0, f64::max);
    tips.iter().zip(reference).map(|(a, b)| d(a, b)).fold(0.0, f64::max) / scale
}

/// The study's model: the paper's 2D scenario with [`ELEMENTS`] elements per link, its reduced
/// model, the initial rigid rotation projected on it, and the undeformed tip of each.
pub struct Model {
    /// The scenario with its modes and reduced model.
    pub setup: Setup,
    /// The reduced model as shooting dynamics.
    pub rom: RomDynamics,
    /// Initial ROM state (rigid rotation at [`OMEGA0`] about the root, projected).
    pub q0: Vec<f64>,
    /// Tip of the undeformed FE structure.
    pub fe_r0: [f64; 3],
    /// Tip of the ROM at `q0`.
    pub rom_r0: [f64; 3],
}

impl Model {
    /// Builds the paper's 2D scenario with [`ELEMENTS`] elements per link and its reduced model.
    pub fn paper_2d() -> Result<Self> {
        let setup = Setup::new(&Scenario::paper_2d(ELEMENTS)?)?;
        let rom = RomDynamics::new(&setup.rom)?;
        let structure = &setup.scenario.structure;
        let x0 = structure.rigid_rotation_state(Vector3::new(0.0, OMEGA0, 0.0), Vector3::zeros());
        let q0 = setup.rom.project_full(&x0, None)?;
        let fe_r0 = {
            let r = structure.reference()[1].r[ELEMENTS];
            [r.x, r.y, r.z]
        };
        let rom_r0 = setup.rom.positions(&q0)?[1][ELEMENTS];
        Ok(Self { setup, rom, q0, fe_r0, rom_r0 })
    }

    /// FE plant tips at the interval ends, `per_interval` steps per interval.
    pub fn fe_tips(&self, per_interval: usize, horizon: f64) -> Result<Tips> {
        fe_tips(&self.setup, per_interval, horizon)
    }

    /// ROM states at the interval ends by `kind` with `substeps` per interval.
    pub fn rom_states(
        &self,
        kind: IntegratorKind,
        substeps: usize,
        horizon: f64,
    ) -> Result<Vec<Vec<f64>>> {
        rom_states(&self.setup, &self.rom, kind, substeps, &self.q0, horizon)
    }

    /// ROM tips of `states`.
    pub fn rom_tips(&self, states: &[Vec<f64>]) -> Result<Tips> {
        rom_tips(&self.setup, states)
    }
}
