//! Study (b), ROM mode count against trajectory error and time (the runs and error measures
//! are `flexmpc_verification::perf::modes`), and study `modes-scaling`, the time and memory of
//! the modal basis against the mesh.

use super::plot::{Chart, Legend, Series};
use super::report::{Fmt, Study, Table};
use super::{ok, timed, Ctx};
use anyhow::Result;
use flexmpc_verification::perf::modes::{
    build_rom, fe_track, initial_state, lawson_tip_error, rom_lawson, rom_run, track_errors, DT,
    FE_ELEMENTS, IMPULSE, LAWSON_SUBSTEPS,
};
use intrinsic_beam::Section;
use modal_rom::{BasisSettings, StructureModel};
use ocp_transcription::{Integrator, IntegratorKind, IntegratorSettings};

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
        let (fe, t_fe) = ok(timed(k, 4.0, || fe_track(&structure, omega0, horizon)))?;
        ctx.tick();
        let amax = fe.iter().fold(0.0f64, |a, t| a.max(t.2.abs()));
        let q_full = initial_state(&structure, omega0);
        let mut s_tip = Series::line(format!("tip position, ω0 = {omega0}"));
        let mut s_ang = Series::line(format!("elbow angle, ω0 = {omega0}"));
        let mut s_law = Series::line(format!("tip position, ω0 = {omega0}, Lawson RK4"));
        let mut errs = Vec::new();
        for &n in counts {
            ctx.progress(&format!("(b) ROM rigid + {n}, ω0 = {omega0}"));
            let r = ok(build_rom(&basis, &model, &structure, n))?;
            let q0 = r.rom.project_full(&q_full, None)?;
            let track = ok(rom_run(&r, &q0, horizon, true))?;
            let (_, t_rom) = ok(timed(k, 4.0, || rom_run(&r, &q0, horizon, false)))?;
            let (et, ea) = track_errors(&track, &fe);
            let model = mpc::RomDynamics::new(&r.rom)?;
            let settings = IntegratorSettings::new(IntegratorKind::LawsonRk4, LAWSON_SUBSTEPS);
            let mut integ = Integrator::new(&model, &settings, IMPULSE.1)?;
            let (states, t_law) =
                ok(timed(k, 4.0, || rom_lawson(&model, &mut integ, &q0, horizon)))?;
            let el = ok(lawson_tip_error(&r.rom, &states, &fe))?;
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
