//! Study (b): ROM mode count against trajectory error (against the FE plant) and time. The
//! paper's 2D two-link (2×20 elements, damped paper section) spun up by a rigid rotation ω0
//! about the root and kicked by a transverse follower tip force; the FE plant (implicit
//! midpoint, `multibody-constraints`) and the modal model on rigid + N elastic modes (implicit
//! midpoint, `ModalRom::midpoint_step`) with the same step, from the same projected state.
//! (The same experiment as the verification case `modal-rom/rom-vs-fe`, rebuilt here on the
//! public crate APIs: the case's helpers are private to the verification crate.)

use super::plot::{Chart, Legend, Series};
use super::report::{Fmt, Study, Table};
use super::{timed, Ctx};
use anyhow::Result;
use intrinsic_beam::rotation::{quat_conj, quat_mul};
use intrinsic_beam::{Amplitude, LoadFrame, PointLoad, Section};
use modal_rom::{BasisSettings, ModalBasis, ModalRom, ModeSelection, RomOptions, StructureModel};
use multibody_constraints::Structure;
use multibody_constraints::{Plant, PlantSettings};
use nalgebra::{Vector3, Vector4, Vector6};
use ocp_transcription::{Integrator, IntegratorKind, IntegratorSettings};

const FE_ELEMENTS: usize = 20;
const DT: f64 = 2e-3;
/// Transverse follower tip force (N) and how long it is held (s).
const IMPULSE: (f64, f64) = (0.05, 0.05);
const SAMPLE_EVERY: usize = 5;

/// Time, tip position, elbow angle.
type Track = Vec<(f64, [f64; 3], f64)>;

/// Elbow angle (planar, about e2) from the end quaternions of the two links.
fn hinge_angle(xa: &Vector4<f64>, xb: &Vector4<f64>) -> f64 {
    let rel = quat_mul(&quat_conj(xa), xb);
    2.0 * rel[2].atan2(rel[0])
}

fn initial_state(structure: &Structure, omega0: f64) -> Vec<f64> {
    structure.rigid_rotation_state(Vector3::new(0.0, omega0, 0.0), Vector3::zeros())
}

fn fe_track(structure: &Structure, omega0: f64, horizon: f64) -> Result<Track> {
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

struct Rom {
    rom: ModalRom,
    /// Row giving the elbow's relative rotation rate from `q1` (planar: rates add).
    rate_row: Vec<f64>,
}

fn build_rom(
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
fn rom_run(r: &Rom, q0: &[f64], horizon: f64, track: bool) -> Result<Track> {
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
fn rom_lawson(
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
const LAWSON_SUBSTEPS: usize = 16;

/// Tip error of states at the interval ends against the FE track (same times), relative to
/// the FE tip excursion.
fn lawson_tip_error(rom: &ModalRom, states: &[Vec<f64>], fe: &Track) -> Result<f64> {
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
fn track_errors(rom: &Track, fe: &Track) -> (f64, f64) {
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

/// Runs study (b).
pub(crate) fn run(ctx: &mut Ctx) -> Result<Study> {
    let (counts, k): (&[usize], usize) =
        if ctx.quick { (&[4, 8, 16], 3) } else { (&[4, 8, 16, 32], 7) };
    let omegas = [0.1, 1.0];
    let horizon = if ctx.quick { 1.0 } else { 2.0 };
    ctx.plan((omegas.len() * (counts.len() + 1) + 1) as u64);
    ctx.progress("(b) modes of the 2D two-link");
    let structure =
        multibody_constraints::samples::paper_2d(Section::paper_2d(), FE_ELEMENTS, 0.0)?;
    let model = StructureModel::new(&structure)?;
    let basis = model.modes(&BasisSettings::default())?;
    ctx.tick();
    let mut table = Table::new(
        "rom-vs-fe",
        format!(
            "ROM (rigid + N elastic modes) against the FE plant, 2×{FE_ELEMENTS} elements, \
             dt = {DT} s, {horizon} s"
        ),
        &[
            ("ω0 (rad/s)", Fmt::Fix(1)),
            ("modes", Fmt::Text),
            ("ROM states", Fmt::Int),
            ("tip error / tip excursion", Fmt::Sci),
            ("elbow-angle error / max |angle|", Fmt::Sci),
            ("max |elbow angle| FE (rad)", Fmt::Sci),
            ("ROM run (s)", Fmt::Fix(3)),
            ("tip error, ROM Lawson RK4", Fmt::Sci),
            ("ROM run, Lawson RK4 (s)", Fmt::Sci),
            ("FE plant run (s)", Fmt::Fix(3)),
            ("FE / ROM time (midpoint, Lawson)", Fmt::Text),
        ],
    );
    let mut chart = Chart::new(
        "error-time",
        format!("(b) ROM against FE plant: error against run time ({horizon} s simulated; labels: elastic modes)"),
        "ROM run time (s): implicit midpoint dt = 2 ms, Lawson RK4 dt = 3.1 ms",
        "max error over time, relative",
    );
    chart.legend = Legend::UpperLeft;
    let mut notes = Vec::new();
    for &omega0 in &omegas {
        ctx.progress(&format!("(b) FE plant, ω0 = {omega0}"));
        let (fe, t_fe) = timed(k, 4.0, || fe_track(&structure, omega0, horizon))?;
        ctx.tick();
        let amax = fe.iter().fold(0.0f64, |a, t| a.max(t.2.abs()));
        let q_full = initial_state(&structure, omega0);
        let mut s_tip = Series::line(format!("tip position, ω0 = {omega0}"));
        let mut s_ang = Series::line(format!("elbow angle, ω0 = {omega0}"));
        let mut s_law = Series::line(format!("tip position, ω0 = {omega0}, Lawson RK4"));
        let mut errs = Vec::new();
        for &n in counts {
            ctx.progress(&format!("(b) ROM rigid + {n}, ω0 = {omega0}"));
            let r = build_rom(&basis, &model, &structure, n)?;
            let q0 = r.rom.project_full(&q_full, None)?;
            let track = rom_run(&r, &q0, horizon, true)?;
            let (_, t_rom) = timed(k, 4.0, || rom_run(&r, &q0, horizon, false))?;
            let (et, ea) = track_errors(&track, &fe);
            let model = mpc::RomDynamics::new(&r.rom)?;
            let settings = IntegratorSettings::new(IntegratorKind::LawsonRk4, LAWSON_SUBSTEPS);
            let mut integ = Integrator::new(&model, &settings, IMPULSE.1)?;
            let (states, t_law) = timed(k, 4.0, || rom_lawson(&model, &mut integ, &q0, horizon))?;
            let el = lawson_tip_error(&r.rom, &states, &fe)?;
            s_law.add(t_law, el, format!("{n}"));
            s_tip.add(t_rom, et, format!("{n}"));
            s_ang.add(t_rom, ea, format!("{n}"));
            errs.push((n, et, ea, t_rom, el, t_law));
            table.push(vec![
                omega0.into(),
                format!("{} + {n}", basis.n_rigid()).into(),
                q0.len().into(),
                et.into(),
                ea.into(),
                amax.into(),
                t_rom.into(),
                el.into(),
                t_law.into(),
                t_fe.into(),
                format!("{:.1}, {:.0}", t_fe / t_rom, t_fe / t_law).into(),
            ]);
            ctx.tick();
        }
        chart.series.push(s_tip);
        chart.series.push(s_law);
        chart.series.push(s_ang);
        let first = errs.first().copied().unwrap_or_default();
        let last = errs.last().copied().unwrap_or_default();
        let e8 = errs.iter().find(|e| e.0 == 8).copied().unwrap_or_default();
        notes.push(format!(
            "ω0 = {omega0}: tip error {:.2e} (rigid + {}) → {:.2e} (rigid + 8) → {:.2e} (rigid + \
             {}); elbow-angle error {:.2e} → {:.2e} (largest FE elbow angle {amax:.1e} rad); ROM \
             run {:.3} → {:.3} s against {t_fe:.3} s for the FE plant. With the controller's \
             Lawson RK4 the rigid + 8 ROM has tip error {:.2e} and runs in {:.2e} s ({:.0}× \
             faster than the FE plant).",
            first.1,
            first.0,
            e8.1,
            last.1,
            last.0,
            first.2,
            last.2,
            first.3,
            last.3,
            e8.4,
            e8.5,
            t_fe / e8.5
        ));
    }
    let mut study = Study::new(
        "b-modes",
        "(b) ROM mode count against trajectory error and time",
        format!(
            "Paper 2D two-link (`multibody_constraints::samples::paper_2d`, damped paper \
             section) at 0°, 2×{FE_ELEMENTS} elements; initial state: rigid rotation ω0 about \
             the root; transverse follower tip force {} N for {} s (the same `Input` in ROM and \
             plant). FE plant: implicit midpoint, dt = {DT} s, Newton 1e-12. ROM: the lowest \
             modes (rigid + N elastic) of the same mesh at 0°, quaternion modes, implicit \
             midpoint (`ModalRom::midpoint_step`, dense Newton, tolerance 1e-12) at the same dt, \
             from the projected initial state. Tip error: max over time of |r_ROM − r_FE| over \
             the max FE tip excursion (Lawson RK4 runs: the ROM with the controller's integrator, \
             16 substeps per 0.05 s, compared at the 0.05 s interval ends); elbow angle: ROM integral of the relative rotation rate \
             against the FE hinge angle, over the largest FE angle. Run times integrate only \
             (no output sampling).",
            IMPULSE.0, IMPULSE.1
        ),
    );
    notes.push(
        "With spin the elbow-angle error does not fall with modes: the modes are fixed at 0° \
         and miss the centrifugal stiffening of the elbow (docs/modal-rom.md §4)."
            .into(),
    );
    study.tables = vec![table];
    study.charts = vec![chart];
    study.notes = notes;
    Ok(study)
}

/// Peak resident memory of this process so far (MB), from `VmHWM` in `/proc/self/status`
/// (NaN where it cannot be read).
fn peak_resident_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb * 1024.0 / 1e6)
}

/// Study `modes-scaling`: time and peak memory of the modal basis that `flexmpc modes`
/// computes (its dense or sparse route, `flexmpc::modes::report`) against the mesh, on the
/// paper's 2D two-link at 0° with its 20 lowest modes.
pub(crate) fn run_scaling(ctx: &mut Ctx) -> Result<Study> {
    let meshes: &[usize] =
        if ctx.quick { &[100, 300, 1000, 2000] } else { &[100, 300, 1000, 2000, 5000] };
    ctx.plan(meshes.len() as u64);
    let mut table = Table::new(
        "scaling",
        "Paper 2D two-link at 0°: the 20 lowest modes against elements per link",
        &[
            ("elements per link", Fmt::Int),
            ("node unknowns n1", Fmt::Int),
            ("route", Fmt::Text),
            ("modes (s)", Fmt::Fix(3)),
            ("peak resident memory so far (MB)", Fmt::Fix(0)),
            ("first elastic ω (rad/s)", Fmt::Fix(6)),
        ],
    );
    for &n in meshes {
        ctx.progress(&format!("modes-scaling, 2 × {n} elements"));
        let structure = multibody_constraints::samples::paper_2d(Section::paper_2d(), n, 0.0)?;
        let est = flexmpc::modes::estimate(&structure);
        let route = match est.route() {
            flexmpc::modes::Route::Dense => "dense",
            flexmpc::modes::Route::Sparse => "sparse",
        };
        let (report, seconds) = timed(3, 5.0, || flexmpc::modes::report(&structure, 20))?;
        let first = report.frequencies_rad_s.get(report.n_rigid).copied().unwrap_or(f64::NAN);
        table.push(vec![
            n.into(),
            est.n1.into(),
            route.into(),
            seconds.into(),
            peak_resident_mb().into(),
            first.into(),
        ]);
        ctx.tick();
    }
    let mut study = Study::new(
        "modes-scaling",
        "Modal basis: time and memory against mesh size",
        "The paper's 2D two-link (paper section, 0°), its 20 lowest constrained modes by the \
         route `flexmpc modes` takes (dense up to 1,200 node unknowns, sparse shift-invert \
         Lanczos above), in process, without the plots.",
    );
    study.tables.push(table);
    study.notes.push(
        "Peak memory is the process high-water mark after each size (sizes ascending, so it \
         bounds each size's peak from above; earlier studies of the same run count too). \
         docs/performance.md has the same curve for the whole command under /usr/bin/time."
            .into(),
    );
    Ok(study)
}
