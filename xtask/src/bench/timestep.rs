//! Study (c): time step against error and time. The paper's 2D two-link spun at ω0 about the
//! root and kicked by a transverse follower tip force for the first 0.05 s: the FE plant
//! (implicit midpoint, `multibody-constraints`) and the paper's reduced model (2 rigid +
//! 4 axial + 4 bending modes with quaternion modes, `mpc::Setup`) integrated by the three
//! shooting integrators of `ocp-transcription` (implicit midpoint, RK4, Lawson RK4 on `W`),
//! each from coarse to fine steps against a tight reference of the same model.

use super::plot::{Chart, Legend, Series};
use super::report::{Fmt, Study, Table};
use super::{orders, timed, Ctx};
use anyhow::Result;
use intrinsic_beam::{Amplitude, LoadFrame, PointLoad};
use mpc::{RomDynamics, Scenario, Setup};
use multibody_constraints::{Plant, PlantSettings};
use nalgebra::{Vector3, Vector6};
use ocp_transcription::{Integrator, IntegratorKind, IntegratorSettings};

const ELEMENTS: usize = 20;
/// Output (and control) interval: every step count divides it.
const INTERVAL: f64 = 0.05;
const OMEGA0: f64 = 1.0;
const KICK: f64 = 0.05;

/// Tip positions at the ends of the output intervals.
type Tips = Vec<[f64; 3]>;

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
            anyhow::bail!("unstable");
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
fn tip_error(tips: &Tips, reference: &Tips, r0: [f64; 3]) -> f64 {
    let d = |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    let scale = reference.iter().map(|r| d(r, &r0)).fold(0.0, f64::max);
    tips.iter().zip(reference).map(|(a, b)| d(a, b)).fold(0.0, f64::max) / scale
}

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
    let setup = Setup::new(&Scenario::paper_2d(ELEMENTS)?)?;
    let model = RomDynamics::new(&setup.rom)?;
    let structure = &setup.scenario.structure;
    let x0 = structure.rigid_rotation_state(Vector3::new(0.0, OMEGA0, 0.0), Vector3::zeros());
    let q0 = setup.rom.project_full(&x0, None)?;
    let fe_r0 = {
        let r = structure.reference()[1].r[ELEMENTS];
        [r.x, r.y, r.z]
    };
    let rom_r0 = setup.rom.positions(&q0)?[1][ELEMENTS];

    ctx.progress(&format!("(c) FE reference, dt = {:.2e}", INTERVAL / fe_ref as f64));
    let fe_reference = fe_tips(&setup, fe_ref, horizon)?;
    ctx.tick();
    let mut lines = Vec::new();
    let mut fe =
        Line { name: "FE plant, implicit midpoint", dt: vec![], err: vec![], time: vec![] };
    for &n in fe_steps {
        ctx.progress(&format!("(c) FE plant, dt = {:.2e}", INTERVAL / n as f64));
        let (tips, t) = timed(k, 6.0, || fe_tips(&setup, n, horizon))?;
        fe.dt.push(INTERVAL / n as f64);
        fe.err.push(tip_error(&tips, &fe_reference, fe_r0));
        fe.time.push(t);
        ctx.tick();
    }
    lines.push(fe);

    ctx.progress("(c) ROM reference (Lawson RK4)");
    let ref_states = rom_states(&setup, &model, IntegratorKind::LawsonRk4, rom_ref, &q0, horizon)?;
    let rom_reference = rom_tips(&setup, &ref_states)?;
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
            match timed(k, 4.0, || rom_states(&setup, &model, kind, n, &q0, horizon)) {
                Ok((states, t)) => {
                    l.err.push(tip_error(&rom_tips(&setup, &states)?, &rom_reference, rom_r0));
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
