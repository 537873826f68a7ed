//! Study (b) of `cargo xtask bench`, ROM mode count against trajectory error (against the FE
//! plant) and time: the paper's 2D two-link (2×20 elements, damped paper section) spun up by a
//! rigid rotation ω0 about the root and kicked by a transverse follower tip force; the FE
//! plant (implicit midpoint, `multibody-constraints`) and the modal model on rigid + N elastic
//! modes (implicit midpoint, `ModalRom::midpoint_step`, and the controller's Lawson RK4) with
//! the same step, from the same projected state. (The experiment of the verification case
//! `modal-rom/rom-vs-fe`, measured here as elbow angle and with run times.)

use intrinsic_beam::rotation::{quat_conj, quat_mul};
use intrinsic_beam::{Amplitude, LoadFrame, PointLoad};
use modal_rom::{ModalBasis, ModalRom, ModeSelection, RomOptions, StructureModel};
use multibody_constraints::{Plant, PlantSettings, Structure};
use nalgebra::{Vector3, Vector4, Vector6};
use ocp_transcription::Integrator;

use super::Result;

/// Elements per link.
pub const FE_ELEMENTS: usize = 20;
/// Time step (s) of the FE plant and of the ROM's implicit midpoint.
pub const DT: f64 = 2e-3;
/// Transverse follower tip force (N) and how long it is held (s).
pub const IMPULSE: (f64, f64) = (0.05, 0.05);
/// Steps between two samples of a track.
pub const SAMPLE_EVERY: usize = 5;

/// Samples of a run: time, tip position, elbow angle.
pub type Track = Vec<(f64, [f64; 3], f64)>;

/// Elbow angle (planar, about e2) from the end quaternions of the two links.
pub fn hinge_angle(xa: &Vector4<f64>, xb: &Vector4<f64>) -> f64 {
    let rel = quat_mul(&quat_conj(xa), xb);
    2.0 * rel[2].atan2(rel[0])
}

/// The rigid rotation at `omega0` (rad/s) about the root's e2.
pub fn initial_state(structure: &Structure, omega0: f64) -> Vec<f64> {
    structure.rigid_rotation_state(Vector3::new(0.0, omega0, 0.0), Vector3::zeros())
}

/// The FE plant's run over `horizon` seconds: kicked at the tip for `IMPULSE.1` s.
pub fn fe_track(structure: &Structure, omega0: f64, horizon: f64) -> Result<Track> {
    let mut plant = Plant::new(structure.clone(), PlantSettings { dt: DT, ..Default::default() })?;
    plant.set_state(&initial_state(structure, omega0))?;
    let tip = FE_ELEMENTS;
    plant.loads_mut(1).point.push(PointLoad {
        node: tip,
        frame: LoadFrame::Follower,
        value: Vector6::new(0.0, 0.0, IMPULSE.0, 0.0, 0.0, 0.0),
        amplitude: Amplitude::Constant,
    });
    let steps = (horizon / DT).round() as usize;
    let on = (IMPULSE.1 / DT).round() as usize;
    let mut track = Vec::new();
    for s in 0..=steps {
        if s % SAMPLE_EVERY == 0 {
            let k = plant.kinematics();
            let r = k[1].r[tip];
            track.push((s as f64 * DT, [r.x, r.y, r.z], hinge_angle(&k[0].xi[tip], &k[1].xi[0])));
        }
        if s == on {
            plant.loads_mut(1).point.clear();
        }
        if s < steps {
            plant.step()?;
        }
    }
    Ok(track)
}

/// A reduced model of the two-link and its elbow-rate row.
pub struct Rom {
    /// The reduced model.
    pub rom: ModalRom,
    /// Row giving the elbow's relative rotation rate from `q1` (planar: rates add).
    pub rate_row: Vec<f64>,
}

/// The ROM on the rigid and the `n_elastic` lowest elastic modes of `basis`, with the two-link's
/// inputs.
pub fn build_rom(
    basis: &ModalBasis,
    model: &StructureModel,
    structure: &Structure,
    n_elastic: usize,
) -> Result<Rom> {
    let sel = basis.select(&ModeSelection::Lowest(basis.n_rigid() + n_elastic))?;
    let inputs = modal_rom::samples::inputs_2d(structure, model)?;
    let rom = ModalRom::new(&sel, Some(&model.damping), &inputs, &RomOptions::default())?;
    let layout = rom.layout();
    let (ia, ib) = (layout.x1_index(0, FE_ELEMENTS, 2), layout.x1_index(1, 0, 2));
    let rate_row = (0..rom.n_modes()).map(|j| sel.phi1()[(ib, j)] - sel.phi1()[(ia, j)]).collect();
    Ok(Rom { rom, rate_row })
}

/// Integrates the ROM over the horizon; with `track` samples tip and elbow angle.
pub fn rom_run(r: &Rom, q0: &[f64], horizon: f64, track: bool) -> Result<Track> {
    let mut q = q0.to_vec();
    let steps = (horizon / DT).round() as usize;
    let on = (IMPULSE.1 / DT).round() as usize;
    let m = r.rom.n_modes();
    let mut u = vec![0.0, 0.0, IMPULSE.0];
    let mut angle = 0.0;
    let mut out = Vec::new();
    for s in 0..=steps {
        if track && s % SAMPLE_EVERY == 0 {
            let pos = r.rom.positions(&q)?;
            out.push((s as f64 * DT, pos[1][FE_ELEMENTS], angle));
        }
        if s == on {
            u = vec![0.0; 3];
        }
        if s < steps {
            let old: Vec<f64> = q[..m].to_vec();
            r.rom.midpoint_step(&mut q, &u, DT, 1e-12, 30)?;
            angle += DT * (0..m).map(|j| r.rate_row[j] * 0.5 * (old[j] + q[j])).sum::<f64>();
        }
    }
    Ok(out)
}

/// Lawson RK4 (the controller's integrator, `L = W`) over intervals of the kick's length with
/// `LAWSON_SUBSTEPS` substeps: the states at the interval ends.
pub fn rom_lawson(
    model: &mpc::RomDynamics,
    integ: &mut Integrator,
    q0: &[f64],
    horizon: f64,
) -> Result<Vec<Vec<f64>>> {
    let intervals = (horizon / IMPULSE.1).round() as usize;
    let mut x = q0.to_vec();
    let mut next = vec![0.0; x.len()];
    let mut out = Vec::with_capacity(intervals);
    for i in 0..intervals {
        let u = if i == 0 { [0.0, 0.0, IMPULSE.0] } else { [0.0; 3] };
        integ.integrate(model, &x, &u, &mut next)?;
        std::mem::swap(&mut x, &mut next);
        out.push(x.clone());
    }
    Ok(out)
}

/// Substeps of the Lawson RK4 runs per 0.05 s interval (dt = 3.1 ms).
pub const LAWSON_SUBSTEPS: usize = 16;

/// Tip error of states at the interval ends against the FE track (same times), relative to
/// the FE tip excursion.
pub fn lawson_tip_error(rom: &ModalRom, states: &[Vec<f64>], fe: &Track) -> Result<f64> {
    let r0 = fe[0].1;
    let d = |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let scale = fe.iter().map(|t| d(&t.1, &r0)).fold(0.0, f64::max);
    let per = (IMPULSE.1 / (DT * SAMPLE_EVERY as f64)).round() as usize;
    let mut e = 0.0f64;
    for (i, q) in states.iter().enumerate() {
        let tip = rom.positions(q)?[1][FE_ELEMENTS];
        e = e.max(d(&tip, &fe[(i + 1) * per].1));
    }
    Ok(e / scale)
}

/// `(tip error, joint-angle error)`: max over time, relative to the FE tip excursion and the
/// largest FE elbow angle.
pub fn track_errors(rom: &Track, fe: &Track) -> (f64, f64) {
    let r0 = fe[0].1;
    let (mut et, mut ea, mut st, mut sa) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (a, b) in rom.iter().zip(fe) {
        let d = (0..3).map(|i| (a.1[i] - b.1[i]).powi(2)).sum::<f64>().sqrt();
        let s = (0..3).map(|i| (b.1[i] - r0[i]).powi(2)).sum::<f64>().sqrt();
        et = et.max(d);
        st = st.max(s);
        ea = ea.max((a.2 - b.2).abs());
        sa = sa.max(b.2.abs());
    }
    (et / st, ea / sa)
}
