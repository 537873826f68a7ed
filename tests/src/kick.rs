//! The elbow kick of docs/mpc.md ("Why the ROM plant is the harder one here"): on the paper's
//! 3D two-link (`Scenario::paper_3d`, 2 × 50 elements), a follower tip force along e2 for
//! 0.4 s, then free motion to 2 s, from rest and from the spin `ω0 (e2 + e3)`, replayed on the
//! FE plant, on the paper's modal model (29) and on the exact-joints model (theory.md §10,
//! its default per-link basis as `--model exact-joints` uses). The FE plant's elbow is the
//! truth: the exact-joints model carries the spin's restoring moment on the bent elbow and
//! must follow it; the paper's model (modes and joint rows linearised at 0°) lacks that
//! moment and drifts under the spin, which is reported, not asserted.

use crate::{Case, CaseOutcome, Metric, Tier};
use mpc::{open_loop, ModalPlant, ModelKind, PlantKind, Scenario, Setup};
use multibody_constraints::Plant;
use nalgebra::Vector3;

/// The case of the kick table.
pub fn cases() -> Vec<Case> {
    vec![Case { name: "mpc/kick-table-3d", tier: Tier::Quick, run: kick_table }]
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// The paper's mesh: 2 × 50 elements.
const ELEMENTS: usize = 50;
/// Output intervals (of 0.05 s) the force is held: 0.4 s.
const PULSE: usize = 8;
/// Output intervals of the run: 2 s.
const INTERVALS: usize = 40;
/// Output intervals between the reported elbow angles: 0.4 s.
const REPORT_EVERY: usize = 8;
/// The exact-joints elbow's allowed deviation from the FE plant's at the reported times:
/// this share of the FE elbow's largest excursion over the run, or this angle, whichever is
/// larger. Measured: 0.01–0.13° (at most 0.9 % of the excursion); the paper's model is off
/// by 0.8° from rest and by 9.5° and 33° under the spin.
const SHARE: f64 = 0.02;
const FLOOR_DEG: f64 = 0.1;

/// One row of the table: tip force e2 amplitude and spin rate.
const ROWS: [(f64, f64); 3] = [(0.1, 0.0), (0.1, 1.0), (0.5, 1.0)];

/// Elbow angle (degrees) at every output interval on the exact-joints model from the FE
/// plant's initial state, advanced by `rom_plant_substeps` implicit-midpoint steps per
/// interval holding each input.
fn exact_joints_elbow(
    setup: &Setup,
    omega0: f64,
    inputs: &[Vec<f64>],
    elbow: usize,
) -> Result<Vec<f64>, String> {
    let sc = &setup.scenario;
    let omega = Vector3::from_column_slice(&sc.omega_direction) * omega0;
    let x0 = sc.structure.rigid_rotation_state(omega, Vector3::from_column_slice(&sc.center));
    let mut fe = Plant::new(sc.structure.clone(), sc.plant).map_err(err)?;
    fe.set_state(&x0).map_err(err)?;
    let mut rom = ModalPlant::new(
        ModelKind::ExactJoints,
        &sc.structure,
        &sc.selection,
        None,
        |s, m| sc.inputs.iter().map(|i| i.modal(s, m)).collect(),
        fe.state(),
        fe.kinematics(),
    )
    .map_err(err)?;
    let dt = sc.output_interval / sc.rom_plant_substeps as f64;
    let angle = |rom: &ModalPlant| -> Result<f64, String> {
        let kin = rom.kinematics().map_err(err)?;
        Ok(rom.joint_angles(&kin)[elbow].to_degrees())
    };
    let mut out = vec![angle(&rom)?];
    for u in inputs {
        for _ in 0..sc.rom_plant_substeps {
            rom.step(u, dt).map_err(err)?;
        }
        out.push(angle(&rom)?);
    }
    Ok(out)
}

fn fmt_row(a: &[f64]) -> String {
    a.iter().map(|v| format!("{v:.1}")).collect::<Vec<_>>().join(" / ")
}

/// The kick table: elbow angles at t = 0.4, 0.8, …, 2.0 s on the three models; the
/// exact-joints elbow within [`SHARE`] of the FE excursion (or [`FLOOR_DEG`]) of the FE
/// elbow at those times; the paper model's largest deviation reported.
fn kick_table() -> CaseOutcome {
    let sc = Scenario::paper_3d(ELEMENTS).map_err(err)?;
    let setup = Setup::new(&sc).map_err(err)?;
    let elbow = setup
        .joint_names
        .iter()
        .position(|n| n == "elbow")
        .ok_or_else(|| "the paper's 3D structure has no joint `elbow`".to_string())?;
    let force = sc
        .inputs
        .iter()
        .position(|i| i.name() == "tip force e2")
        .ok_or_else(|| "the 3D scenario has no input `tip force e2`".to_string())?;
    let nu = sc.inputs.len();
    eprintln!(
        "| tip force e2 for 0.4 s, then free | elbow at t = 0.4 / 0.8 / 1.2 / 1.6 / 2.0 s, \
         FE plant | same, paper's modal model | same, exact-joints model |"
    );
    let mut metrics = Vec::new();
    for (amp, omega0) in ROWS {
        let mut inputs = vec![vec![0.0; nu]; INTERVALS];
        for u in inputs.iter_mut().take(PULSE) {
            u[force] = amp;
        }
        let fe: Vec<f64> = open_loop(&setup, omega0, &inputs, PlantKind::Fe)
            .map_err(err)?
            .iter()
            .map(|r| r.joint_angles[elbow].to_degrees())
            .collect();
        let paper: Vec<f64> = open_loop(&setup, omega0, &inputs, PlantKind::Rom)
            .map_err(err)?
            .iter()
            .map(|r| r.joint_angles[elbow].to_degrees())
            .collect();
        let exact = exact_joints_elbow(&setup, omega0, &inputs, elbow)?;
        let at = |a: &[f64]| -> Vec<f64> {
            (REPORT_EVERY..=INTERVALS).step_by(REPORT_EVERY).map(|k| a[k]).collect()
        };
        let (f, p, e) = (at(&fe), at(&paper), at(&exact));
        let excursion = fe.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let dev = |a: &[f64]| f.iter().zip(a).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        let (dp, de) = (dev(&p), dev(&e));
        eprintln!(
            "| {amp}, {} (ω0 = {omega0}) | {}° | {}° | {}° |",
            if omega0 == 0.0 { "from rest" } else { "spinning" },
            fmt_row(&f),
            fmt_row(&p),
            fmt_row(&e)
        );
        eprintln!(
            "  FE excursion {excursion:.2}°; largest deviation from FE at the reported times: \
             paper {dp:.2}°, exact joints {de:.2}°"
        );
        let label = format!("tip force {amp}, ω0 = {omega0}");
        metrics.push(Metric::at_most(
            format!("{label}: exact-joints elbow − FE elbow (deg)"),
            de,
            (SHARE * excursion).max(FLOOR_DEG),
        ));
        // reported only: the paper's model lacks the spin's restoring moment (docs/mpc.md)
        metrics.push(Metric::at_most(
            format!("{label}: paper-model elbow − FE elbow (deg, reported)"),
            dp,
            f64::INFINITY,
        ));
    }
    Ok(metrics)
}
