//! Study (c): time step against error and time — the table, plots and notes. The model, the
//! runs and the error measure are `flexmpc_verification::perf::timestep`: the paper's 2D
//! two-link spun and kicked, integrated by the FE plant and by the paper's reduced model with
//! the three shooting integrators, each from coarse to fine steps against a tight reference of
//! the same model.

use super::plot::{Chart, Legend, Series};
use super::report::{Fmt, Study, Table};
use super::{ok, orders, timed, Ctx};
use anyhow::Result;
use flexmpc_verification::perf::timestep::{
    tip_error, IntegratorKind, Model, ELEMENTS, INTERVAL, KICK, OMEGA0,
};

struct Line {
    name: &'static str,
    dt: Vec<f64>,
    err: Vec<f64>,
    time: Vec<f64>,
}

/// Runs study (c).
pub(crate) fn run(ctx: &mut Ctx) -> Result<Study> {
    let quick = ctx.quick;
    let horizon = 1.0;
    let (fe_steps, fe_ref, rom_steps, rom_ref, k): (&[usize], usize, &[usize], usize, usize) =
        if quick {
            (&[4, 8, 16, 32], 256, &[1, 2, 4, 8, 16, 32], 1024, 3)
        } else {
            (&[4, 8, 16, 32, 64, 128], 512, &[1, 2, 4, 8, 16, 32, 64, 128], 2048, 7)
        };
    ctx.plan((fe_steps.len() + 1 + 3 * rom_steps.len() + 1) as u64);
    ctx.progress("(c) setup of the paper's 2D reduced model");
    let model = ok(Model::paper_2d())?;
    let (fe_r0, rom_r0) = (model.fe_r0, model.rom_r0);

    ctx.progress(&format!("(c) FE reference, dt = {:.2e}", INTERVAL / fe_ref as f64));
    let fe_reference = ok(model.fe_tips(fe_ref, horizon))?;
    ctx.tick();
    let mut lines = Vec::new();
    let mut fe =
        Line { name: "FE plant, implicit midpoint", dt: vec![], err: vec![], time: vec![] };
    for &n in fe_steps {
        ctx.progress(&format!("(c) FE plant, dt = {:.2e}", INTERVAL / n as f64));
        let (tips, t) = ok(timed(k, 6.0, || model.fe_tips(n, horizon)))?;
        fe.dt.push(INTERVAL / n as f64);
        fe.err.push(tip_error(&tips, &fe_reference, fe_r0));
        fe.time.push(t);
        ctx.tick();
    }
    lines.push(fe);

    ctx.progress("(c) ROM reference (Lawson RK4)");
    let ref_states = ok(model.rom_states(IntegratorKind::LawsonRk4, rom_ref, horizon))?;
    let rom_reference = ok(model.rom_tips(&ref_states))?;
    ctx.tick();
    for (name, kind) in [
        ("ROM, implicit midpoint", IntegratorKind::ImplicitMidpoint),
        ("ROM, RK4", IntegratorKind::Rk4),
        ("ROM, Lawson RK4", IntegratorKind::LawsonRk4),
    ] {
        let mut l = Line { name, dt: vec![], err: vec![], time: vec![] };
        for &n in rom_steps {
            ctx.progress(&format!("(c) {name}, dt = {:.2e}", INTERVAL / n as f64));
            l.dt.push(INTERVAL / n as f64);
            match timed(k, 4.0, || model.rom_states(kind, n, horizon)) {
                Ok((states, t)) => {
                    l.err.push(tip_error(&ok(model.rom_tips(&states))?, &rom_reference, rom_r0));
                    l.time.push(t);
                }
                Err(_) => {
                    // unstable or Newton failure: recorded as a missing error
                    l.err.push(f64::INFINITY);
                    l.time.push(f64::NAN);
                }
            }
            ctx.tick();
        }
        lines.push(l);
    }

    let mut table = Table::new(
        "steps",
        format!(
            "Tip error against time step ({horizon} s simulated, ω0 = {OMEGA0} rad/s, 2×{ELEMENTS} \
             elements; FE reference dt = {:.2e} s, ROM reference Lawson RK4 dt = {:.2e} s)",
            INTERVAL / fe_ref as f64,
            INTERVAL / rom_ref as f64
        ),
        &[
            ("model, integrator", Fmt::Text),
            ("dt (s)", Fmt::Sci),
            ("tip error / tip excursion", Fmt::Sci),
            ("observed order", Fmt::Fix(2)),
            ("run time (s)", Fmt::Sci),
        ],
    );
    let mut c_time = Chart::new(
        "error-time",
        format!(
            "(c) Time step: tip error against run time ({horizon} s simulated; labels: dt in ms)"
        ),
        "run time (s)",
        "tip error / tip excursion",
    );
    c_time.legend = Legend::LowerLeft;
    let mut c_dt = Chart::new(
        "error-dt",
        "(c) Time step: tip error against dt (observed order in the legend)",
        "time step dt (s)",
        "tip error / tip excursion",
    );
    let mut notes = Vec::new();
    for l in &lines {
        let ord = orders(&l.dt, &l.err);
        let last_order = ord.iter().rev().find(|o| o.is_finite()).copied().unwrap_or(f64::NAN);
        let mut st = Series::line(l.name);
        let mut sd = Series::line(format!("{} (order {last_order:.2})", l.name));
        for i in 0..l.dt.len() {
            table.push(vec![
                l.name.into(),
                l.dt[i].into(),
                l.err[i].into(),
                ord[i].into(),
                l.time[i].into(),
            ]);
            let label = format!("{:.2}", l.dt[i] * 1e3);
            st.add(l.time[i], l.err[i], label);
            sd.add(l.dt[i], l.err[i], String::new());
        }
        c_time.series.push(st);
        c_dt.series.push(sd);
        let stable: Vec<usize> = (0..l.dt.len()).filter(|&i| l.err[i].is_finite()).collect();
        let coarsest = stable.first().map(|&i| l.dt[i]).unwrap_or(f64::NAN);
        let mut text = format!(
            "{}: observed order {last_order:.2} at the finest steps; coarsest stable dt \
             {coarsest:.2e} s",
            l.name
        );
        for goal in [1e-3, 1e-5] {
            let cheapest = (0..l.dt.len())
                .filter(|&i| l.err[i] <= goal)
                .min_by(|&a, &b| l.time[a].total_cmp(&l.time[b]));
            text.push_str(&match cheapest {
                Some(i) => format!(
                    "; tip error ≤ {goal:.0e} cheapest at dt = {:.2e} s ({:.2e} s of run time)",
                    l.dt[i], l.time[i]
                ),
                None => format!("; tip error never ≤ {goal:.0e} in the measured range"),
            });
        }
        text.push('.');
        notes.push(text);
    }
    let mut study = Study::new(
        "c-timestep",
        "(c) Time step against error and time",
        format!(
            "Paper 2D two-link, 2×{ELEMENTS} elements, initial rigid rotation ω0 = {OMEGA0} rad/s \
             about the root, transverse follower tip force {KICK} N over the first {INTERVAL} s, \
             {horizon} s simulated. FE plant: `multibody_constraints::Plant` (implicit midpoint, \
             Newton 1e-12) at dt = {INTERVAL}/n. ROM: the paper's selection (2 rigid + 4 axial + \
             4 bending, quaternion modes, `mpc::Setup`) through `mpc::RomDynamics` and \
             `ocp_transcription::Integrator` over {INTERVAL} s intervals with n substeps (implicit \
             midpoint with Newton 1e-13, RK4, Lawson RK4 with `L = W`). Error: max over the \
             interval ends of the tip-position error against the same model's reference run, \
             over the reference's largest tip excursion. `inf`: the run diverged."
        ),
    );
    study.tables = vec![table];
    study.charts = vec![c_time, c_dt];
    study.notes = notes;
    Ok(study)
}
