//! `flexmpc mpc` and `flexmpc sweep`: closed loops of a scene's `[scenario]` with the `mpc`
//! crate (paper §4–5, eqs. 33–36), written as CSV time series and JSON solver logs.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{bail, Context, Result};
use mpc::{ControllerKind, PlantKind, RunResult, Setup};
use rayon::prelude::*;

use crate::scene::{Control, Scene};

/// Command-line overrides of the scene's `[scenario]` / `[controller]`.
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    /// `--controller`.
    pub controller: Option<ControllerKind>,
    /// `--plant`.
    pub plant: Option<PlantKind>,
    /// `--omega0` (one value for `mpc`).
    pub omega0: Option<f64>,
    /// `--duration` (s).
    pub duration: Option<f64>,
    /// `--model`; `exact-joints` also switches off the joint-angle check of the plans (it
    /// reads the paper model's state) and the linear MPC fallback (the linear MPC is the model
    /// linearised at the reference angle, the range the exact-joints model is built to leave).
    pub model: Option<mpc::ModelKind>,
}

/// The scene's closed-loop setup with `overrides` applied and checked.
pub fn control_of(scene: &Scene, overrides: &Overrides) -> Result<Control> {
    let Some(c) = &scene.control else {
        bail!(
            "{}: no [scenario] section: `flexmpc mpc`/`sweep` need [scenario], [modes] with a \
             mode set and control inputs (`control = true`); see scenes/paper-2d-mpc.toml",
            scene.file.display()
        );
    };
    let mut c = c.clone();
    if let Some(k) = overrides.controller {
        c.controller.kind = k;
    }
    if let Some(p) = overrides.plant {
        c.plant = p;
    }
    if let Some(w) = overrides.omega0 {
        if !w.is_finite() {
            bail!("--omega0 must be finite, got {w}");
        }
        c.omega0 = w;
    }
    if let Some(d) = overrides.duration {
        c.scenario.duration = d;
    }
    if let Some(m) = overrides.model {
        c.controller.model = m;
        if m == mpc::ModelKind::ExactJoints {
            c.controller.plan_joint_limit_deg = None;
            c.controller.fallback_to_lmpc = false;
        }
    }
    if c.controller.model == mpc::ModelKind::ExactJoints {
        // `--controller lmpc` with the exact-joints model, say (a sweep checks each kind)
        c.controller.validate().map_err(|e| {
            anyhow::anyhow!("{}: with --model / [controller] model: {e}", scene.file.display())
        })?;
    }
    // the library's rules; a rule on the duration is the flag's
    c.scenario.validate().map_err(|e| match &e {
        mpc::MpcError::Invalid { field, value, reason } if field == "duration" => {
            anyhow::anyhow!("{}: --duration {value} {reason}", scene.file.display())
        }
        _ => anyhow::anyhow!(
            "{}: the scenario with the command-line overrides is invalid: {e}",
            scene.file.display()
        ),
    })?;
    Ok(c)
}

/// How a run writes its outputs.
#[derive(Clone, Copy, Debug)]
pub struct OutputOptions {
    /// No progress bar (`--quiet`, `--json`).
    pub quiet: bool,
    /// Write the measured timings ([`crate::timings::FILES`]); `false` (`--no-timings`)
    /// leaves them out (and removes stale ones), so that two runs of the same inputs give
    /// byte-identical output folders.
    pub timings: bool,
}

impl Default for OutputOptions {
    /// Progress bar shown, timings written.
    fn default() -> Self {
        Self { quiet: false, timings: true }
    }
}

pub use crate::progress::progress_bar;

/// The summary of one run (the closed-loop metrics, the strategy counts and errors) and
/// its measured timings (`solve_time_*`, `wall_time_s`): what `--json` prints on stdout. The
/// files get [`crate::timings::summary_without_timings`] instead.
pub fn summary_json(r: &RunResult) -> serde_json::Value {
    let mut v = serde_json::to_value(&r.summary).unwrap_or(serde_json::Value::Null);
    if let serde_json::Value::Object(m) = &mut v {
        m.insert("wall_time_s".into(), serde_json::json!(r.wall_time_s));
        m.insert("samples".into(), serde_json::json!(r.samples.len()));
    }
    v
}

/// What `flexmpc mpc` wrote.
pub struct MpcOutput {
    /// The run.
    pub result: RunResult,
    /// The setup after overrides.
    pub control: Control,
    /// `timeseries.csv`.
    pub csv: PathBuf,
    /// `samples.json` (per-sample solver log).
    pub samples: PathBuf,
    /// `summary.json`.
    pub summary: PathBuf,
    /// `index.html`.
    pub report: PathBuf,
    /// The timing files (empty with `--no-timings`).
    pub timings: Vec<PathBuf>,
}

/// One closed loop of `scene` into `out`: `timeseries.csv`, `samples.json`,
/// `snapshots.json`, `summary.json` and the report `index.html` with its figures — each a
/// pure function of the inputs — and, with `opts.timings`, the measured timings
/// (`timings.json`, `timings.csv`, `solve_times.svg`).
pub fn run_mpc(
    scene: &Scene,
    overrides: &Overrides,
    out: &Path,
    opts: OutputOptions,
) -> Result<MpcOutput> {
    run_mpc_repeated(scene, overrides, out, opts, 1)
}

/// [`run_mpc`] with the closed loop run `repeat ≥ 1` times: every output is the first run's
/// (the others must agree with it apart from their timings, else an error), and each
/// sample's measured times are the smallest over the runs
/// ([`mpc::RunResult::keep_fastest`]): the cost of the sample's work on this machine with the
/// interference of other processes filtered out (`flexmpc mpc --repeat N`).
pub fn run_mpc_repeated(
    scene: &Scene,
    overrides: &Overrides,
    out: &Path,
    opts: OutputOptions,
    repeat: usize,
) -> Result<MpcOutput> {
    if repeat == 0 {
        bail!("--repeat: must be at least 1, got 0");
    }
    let control = control_of(scene, overrides)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let bar = progress_bar(None, opts.quiet, "modes and reduced model");
    let setup = Setup::new(&control.scenario)
        .with_context(|| format!("setting up the controller of {}", scene.file.display()))?;
    bar.set_message(format!(
        "{} closed loop, ω0 = {}, {:.2} s of motion ({} plant)",
        control.controller.kind.name(),
        control.omega0,
        control.scenario.duration,
        control.plant.name()
    ));
    let run = || {
        mpc::run(&setup, control.omega0, &control.controller, control.plant)
            .with_context(|| format!("closed loop of {}", scene.file.display()))
    };
    let mut result = run()?;
    for k in 1..repeat {
        bar.set_message(format!("closed loop, repetition {} of {repeat}", k + 1));
        result.keep_fastest(&run()?).with_context(|| format!("repetition {}", k + 1))?;
    }
    bar.set_message("report");
    let csv = out.join("timeseries.csv");
    write_timeseries(&result, &csv)?;
    let samples = out.join("samples.json");
    std::fs::write(
        &samples,
        serde_json::to_string_pretty(&crate::timings::samples_without_timings(&result))?,
    )?;
    std::fs::write(out.join("snapshots.json"), serde_json::to_string(&result.snapshots)?)?;
    let summary = out.join("summary.json");
    std::fs::write(
        &summary,
        serde_json::to_string_pretty(&crate::timings::summary_without_timings(&result))?,
    )?;
    let timings = if opts.timings {
        crate::timings::write_run(&result, control.scenario.mpc.timing.sampling, out)?
    } else {
        crate::timings::remove(out)?;
        Vec::new()
    };
    let report =
        crate::report::write(scene, &control, &result, Some(&setup.rom), out, opts.timings)?;
    bar.finish_and_clear();
    Ok(MpcOutput { result, control, csv, samples, summary, report, timings })
}

pub use crate::results::{write_timeseries, SweepRun};

/// What `flexmpc sweep` wrote.
pub struct SweepOutput {
    /// Runs, controllers outer, ω0 inner (the order of the scene / command line).
    pub runs: Vec<SweepRun>,
    /// `sweep.csv`.
    pub csv: PathBuf,
    /// `sweep.json`.
    pub json: PathBuf,
    /// `cost.svg` (Fig. 6 style).
    pub plot: PathBuf,
    /// `inputs.svg` (Fig. 10 style) and `snapshots.svg` (Figs. 7, 9 style).
    pub figures: Vec<PathBuf>,
    /// The timing files (empty with `--no-timings`).
    pub timings: Vec<PathBuf>,
    /// `index.html`: the sweep's report.
    pub report: PathBuf,
}

/// Parses `--omega0`: a list `0.5,1,2` or a range `start:stop:step` (stop included).
pub fn parse_omegas(text: &str) -> Result<Vec<f64>> {
    let num = |s: &str| -> Result<f64> {
        let v: f64 =
            s.trim().parse().with_context(|| format!("--omega0: `{s}` is not a number"))?;
        if !v.is_finite() {
            bail!("--omega0: `{s}` is not finite");
        }
        Ok(v)
    };
    let parts: Vec<&str> = text.split(':').collect();
    match parts.len() {
        1 => text.split(',').map(num).collect(),
        3 => {
            let (a, b, h) = (num(parts[0])?, num(parts[1])?, num(parts[2])?);
            if h <= 0.0 || b < a {
                bail!("--omega0 {text}: a range is start:stop:step with step > 0, stop ≥ start");
            }
            let n = ((b - a) / h + 1e-9).floor() as usize;
            if n > 10_000 {
                bail!("--omega0 {text}: more than 10000 values");
            }
            // a + k h, rounded to 12 digits so 0.1 steps print as 0.3, not 0.30000000000000004
            Ok((0..=n).map(|k| ((a + k as f64 * h) * 1e12).round() / 1e12).collect())
        }
        _ => bail!("--omega0 `{text}`: give a list `0.5,1,2` or a range `start:stop:step`"),
    }
}

/// Every `omegas` × `kinds` closed loop of `scene`, in parallel (rayon's global pool), into
/// `out`: `sweep.csv`, `sweep.json`, `cost.svg` (Fig. 6), `inputs.svg` (Fig. 10),
/// `snapshots.svg` (Figs. 7, 9) and per run `runs/<controller>-w<ω0>.csv` and
/// `runs/<controller>-w<ω0>-snapshots.svg`, the report `index.html` — each a pure function of the inputs, in the
/// order of the input (controllers outer, ω0 inner), whatever order the runs finish in — and,
/// with `opts.timings`, `timings.json`, `timings.csv` and `solve_times.svg`.
pub fn run_sweep(
    scene: &Scene,
    overrides: &Overrides,
    omegas: &[f64],
    kinds: &[ControllerKind],
    out: &Path,
    opts: OutputOptions,
) -> Result<SweepOutput> {
    run_sweep_models(scene, overrides, &[], omegas, kinds, out, opts)
}

/// [`run_sweep`] for several controller models: every `models` × `kinds` × `omegas` closed
/// loop (models outermost) on the same plant, drawn on the same axes (`cost.svg`: one colour
/// per ω0, one line style per model) and listed in the same table; the runs of the
/// exact-joints model are `runs/<controller>-exact-w<ω0>.*`. Each model runs with the scene's
/// settings and what `--model` implies for it ([`control_of`]); an empty `models` is the
/// scene's model (or `overrides.model`).
pub fn run_sweep_models(
    scene: &Scene,
    overrides: &Overrides,
    models: &[mpc::ModelKind],
    omegas: &[f64],
    kinds: &[ControllerKind],
    out: &Path,
    opts: OutputOptions,
) -> Result<SweepOutput> {
    if omegas.is_empty() || kinds.is_empty() {
        bail!("a sweep needs at least one ω0 and one controller");
    }
    let control = control_of(scene, overrides)?;
    // one setup per model: the scene's own model (or `--model`) keeps `overrides` as given
    let mut controls: Vec<Control> = Vec::new();
    for &m in models {
        if controls.iter().any(|c| c.controller.model == m) {
            continue;
        }
        controls.push(if m == control.controller.model {
            control.clone()
        } else {
            control_of(scene, &Overrides { model: Some(m), ..overrides.clone() })?
        });
    }
    if controls.is_empty() {
        controls.push(control.clone());
    }
    std::fs::create_dir_all(out.join("runs"))
        .with_context(|| format!("creating {}", out.display()))?;
    let setup = Setup::new(&control.scenario)
        .with_context(|| format!("setting up the controller of {}", scene.file.display()))?;
    let jobs: Vec<(&Control, ControllerKind, f64)> = controls
        .iter()
        .flat_map(|c| kinds.iter().flat_map(move |&k| omegas.iter().map(move |&w| (c, k, w))))
        .collect();
    let bar = progress_bar(Some(jobs.len() as u64), opts.quiet, "closed loops");
    let done = AtomicUsize::new(0);
    let runs: Vec<SweepRun> = jobs
        .par_iter()
        .map(|&(c, kind, omega0)| {
            let mut settings = c.controller.clone();
            settings.kind = kind;
            let result =
                mpc::run(&setup, omega0, &settings, control.plant).map_err(|e| e.to_string());
            bar.set_position(done.fetch_add(1, Ordering::SeqCst) as u64 + 1);
            SweepRun { controller: kind, model: settings.model, omega0, result }
        })
        .collect();
    bar.finish_and_clear();
    let planar =
        matches!(control.scenario.structure.components(), intrinsic_beam::Components::Planar);
    let csv = out.join("sweep.csv");
    crate::results::write_sweep_csv(&runs, control.plant.name(), &csv)?;
    let mut summaries = Vec::new();
    for r in &runs {
        match &r.result {
            Ok(res) => {
                let stem = r.stem();
                write_timeseries(res, &out.join("runs").join(format!("{stem}.csv")))?;
                crate::figures::snapshots_svg(
                    res,
                    planar,
                    &out.join("runs").join(format!("{stem}-snapshots.svg")),
                )?;
                summaries.push(crate::timings::summary_without_timings(res));
            }
            Err(e) => {
                summaries.push(serde_json::json!({
                    "omega0": r.omega0,
                    "controller": r.controller.name(),
                    "model": r.model.name(),
                    "plant": control.plant.name(),
                    "stabilised": false,
                    "error": e,
                }));
            }
        }
    }
    let json = out.join("sweep.json");
    std::fs::write(&json, serde_json::to_string_pretty(&summaries)?)?;
    let plot = out.join("cost.svg");
    crate::figures::sweep_cost(&plot, &scene.name, &runs)?;
    let inputs = out.join("inputs.svg");
    crate::figures::sweep_inputs(&inputs, &scene.name, &control.scenario.inputs, &runs)?;
    let snapshots = out.join("snapshots.svg");
    crate::figures::sweep_snapshots_svg(&runs, planar, &snapshots)?;
    let timings = if opts.timings {
        crate::timings::write_sweep(&runs, control.scenario.mpc.timing.sampling, out)?
    } else {
        crate::timings::remove(out)?;
        Vec::new()
    };
    let report = crate::report::write_sweep(scene, &control, &runs, out, opts.timings)?;
    Ok(SweepOutput { runs, csv, json, plot, figures: vec![inputs, snapshots], timings, report })
}

/// `flexmpc ocp`: solves the first sample's optimal control problem alone (from the projected
/// initial state of a run with the scene's disturbance) and returns its cost, control
/// sequence, KKT residual, status, iterations and solve time (thread CPU) as JSON; with
/// `export`, also writes the whole problem (modal model export plus `ocp.json`: weights,
/// references, bounds, horizon, `Nc`, integrator, initial state) so that another solver can
/// solve exactly the same problem.
///
/// Either controller model: the paper's (14)–(29), or the exact-joints model (theory.md §10),
/// whose problem is that of the closed loop's first sample ([`mpc::first_sample_exact`]: the
/// FE state projected onto the exact-joints state, the joint commands' references at the
/// shooting nodes' times). The export writes the controller model's own format: modal-rom's
/// model export for the paper's model, the exact-joints export (`model.json` of format
/// `flexmpc-exact-joints-rom` and its arrays) for the exact-joints model; `ocp.json` names it
/// (`model`) and holds the references at the shooting nodes when they vary.
///
/// With `converge` (NMPC), the problem is solved to convergence from the linear MPC plan by a
/// full SQP twice, with [`ocp_transcription::SqpSettings::converge`] (merit line search) and
/// [`ocp_transcription::SqpSettings::converge_filter`] (KKT tolerance 1e-8, Gauss–Newton then
/// exact Hessian; where the model or the integrator has no second derivatives, e.g. the
/// exact-joints model with the implicit midpoint rule, Gauss–Newton then the quasi-Newton
/// estimate of [`ocp_transcription::SqpSettings::converge_quasi_newton`]), whatever the
/// scene's real-time settings, and the better result
/// ([`ocp_transcription::SqpStats::better_than`]) is reported (`line_search`); when the
/// nonlinear model is not finite at the plan's nodes, the plan's controls rolled out from the
/// initial state are the start. `optimum` says whether the status is `Solved`.
/// Without it the scene's controller takes its first sample; a real-time iteration is
/// reported as such (`real_time_iteration`): `cost` is that of the returned plan (after the
/// step), and the KKT residual, only known at the point before the step, is
/// `kkt_before_step` (`kkt` is then null).
pub fn first_sample(
    scene: &Scene,
    overrides: &Overrides,
    export: Option<&Path>,
    converge: bool,
) -> Result<serde_json::Value> {
    let control = control_of(scene, overrides)?;
    let setup = Setup::new(&control.scenario)
        .with_context(|| format!("setting up the controller of {}", scene.file.display()))?;
    let mut v = serde_json::json!({
        "omega0": control.omega0,
        "controller": control.controller.kind.name(),
        "model": control.controller.model.name(),
        "export": export,
    });
    let fields = match control.controller.model {
        mpc::ModelKind::Paper => {
            let problem = match export {
                Some(dir) => {
                    std::fs::create_dir_all(dir)
                        .with_context(|| format!("creating {}", dir.display()))?;
                    mpc::export_first_sample(&setup, control.omega0, &control.controller, dir)?
                }
                None => mpc::first_sample_problem(&setup, control.omega0, &control.controller)?,
            };
            let first = FirstSample {
                weights: &setup.weights,
                schedule: None,
                x0: &problem.x0,
                inputs: &problem.inputs,
            };
            solve_first(&control, mpc::RomDynamics::new(&setup.rom)?, &first, converge)?
        }
        mpc::ModelKind::ExactJoints => {
            let p = match export {
                Some(dir) => {
                    std::fs::create_dir_all(dir)
                        .with_context(|| format!("creating {}", dir.display()))?;
                    mpc::export_first_sample_exact(
                        &setup,
                        control.omega0,
                        &control.controller,
                        dir,
                    )?
                    .0
                }
                None => mpc::first_sample_exact(&setup, control.omega0, &control.controller)?,
            };
            let first = FirstSample {
                weights: &p.weights,
                schedule: p.schedule.as_ref(),
                x0: &p.x0,
                inputs: p.dynamics.rom().input_names(),
            };
            solve_first(&control, p.dynamics.clone(), &first, converge)?
        }
    };
    if let (Some(m), Some(f)) = (v.as_object_mut(), fields.as_object()) {
        for (k, x) in f {
            m.insert(k.clone(), x.clone());
        }
    }
    Ok(v)
}

/// The data of a first sample's problem on either model.
struct FirstSample<'a> {
    weights: &'a mpc::Weights,
    schedule: Option<&'a mpc::ReferenceSchedule>,
    x0: &'a [f64],
    inputs: &'a [String],
}

/// Solves the first sample's problem on `model` ([`first_sample`]) and returns its fields.
fn solve_first<D: ocp_transcription::Dynamics + Clone>(
    control: &Control,
    model: D,
    first: &FirstSample<'_>,
    converge: bool,
) -> Result<serde_json::Value> {
    let mpc_settings = &control.scenario.mpc;
    let nu = model.nu();
    let mut ocp = ocp_transcription::Ocp::new(
        first.x0.len(),
        nu,
        mpc_settings.timing.horizon,
        mpc_settings.timing.intervals,
    )?;
    ocp.q = first.weights.q.clone();
    ocp.r = first.weights.r.clone();
    ocp.x_ref = first.weights.x_ref.clone();
    ocp.u_min = nalgebra::DVector::from_element(nu, -mpc_settings.cost.u_max);
    ocp.u_max = nalgebra::DVector::from_element(nu, mpc_settings.cost.u_max);
    if let Some(s) = first.schedule {
        // the plan starts at t = 0: references at the nodes' times, as in the closed loop
        ocp.x_ref = nalgebra::DVector::from_vec(s.at(0.0));
        ocp.x_ref_nodes = s
            .nodes(0.0, ocp.interval(), ocp.intervals)
            .into_iter()
            .map(nalgebra::DVector::from_vec)
            .collect();
    }
    let rows = |u: &[nalgebra::DVector<f64>]| -> Vec<Vec<f64>> {
        u.iter().map(|u| u.iter().copied().collect()).collect()
    };
    let head = serde_json::json!({ "inputs": first.inputs, "n_state": first.x0.len() });
    let fields = if converge && control.controller.kind == ControllerKind::Nmpc {
        use ocp_transcription::{Globalisation, SqpMode, SqpSettings, SqpSolver, SqpStatus, Start};
        let integrator = control.controller.integrator.clone();
        let lq = SqpSettings {
            mode: SqpMode::LinearQuadratic,
            globalisation: Globalisation::FullStep,
            max_iterations: 2,
            integrator: integrator.clone(),
            ..SqpSettings::default()
        };
        let mut lmpc = SqpSolver::new(model.clone(), ocp.clone(), lq)?;
        lmpc.solve(first.x0)?;
        // the merit and the filter line search from the same start; the better result is kept
        type Attempt<D> = (SqpSolver<D>, ocp_transcription::SqpStats, &'static str, Start);
        let mut best: Option<Attempt<D>> = None;
        let mut time = 0.0;
        // the exact Hessian needs the model's second derivatives and an explicit integrator;
        // otherwise the quasi-Newton estimate of the dynamics' curvature takes its place
        let second_order = model.has_second_order()
            && integrator.kind != ocp_transcription::IntegratorKind::ImplicitMidpoint;
        let hessian = if second_order {
            SqpSettings::converge(integrator.clone()).hessian
        } else {
            SqpSettings::converge_quasi_newton(integrator.clone()).hessian
        };
        for (name, settings) in [
            ("merit", SqpSettings { hessian, ..SqpSettings::converge(integrator.clone()) }),
            ("filter", SqpSettings { hessian, ..SqpSettings::converge_filter(integrator.clone()) }),
        ] {
            let mut nmpc = SqpSolver::new(model.clone(), ocp.clone(), settings)?;
            for (d, s) in nmpc.states_mut().iter_mut().zip(lmpc.states()) {
                d.copy_from(s);
            }
            for (d, s) in nmpc.controls_mut().iter_mut().zip(lmpc.controls()) {
                d.copy_from(s);
            }
            // thread CPU (the solves run on this thread), not inflated by other processes
            let (cpu, r) =
                ocp_transcription::thread_cpu_timed(|| nmpc.solve_with_fallback_starts(first.x0));
            let (st, start) = r?;
            time += cpu;
            if best.as_ref().is_none_or(|(_, b, _, _)| st.better_than(b)) {
                best = Some((nmpc, st, name, start));
            }
        }
        let (nmpc, st, line_search, start) = best.context("no converge attempt ran")?;
        serde_json::json!({
            "mode": "converge",
            "optimum": st.status == SqpStatus::Solved,
            "real_time_iteration": false,
            "cost": st.cost,
            "kkt": st.kkt,
            "constraint_violation": st.constraint_violation,
            "status": format!("{:?}", st.status),
            "strategy": "sqp",
            "line_search": line_search,
            "start": format!("{start:?}"),
            "iterations": st.iterations,
            "solve_time_s": time,
            "controls": rows(nmpc.controls()),
        })
    } else {
        let mut ctrl =
            mpc::Controller::new(model, first.weights, mpc_settings, &control.controller)?;
        if let Some(s) = first.schedule {
            ctrl.set_reference_schedule(s.clone())?;
        }
        let report = ctrl.step(0.0, first.x0)?;
        let (states, controls) = ctrl.plan();
        let rti = report.status == "RealTimeIteration";
        let (cost, kkt) = if rti {
            (serde_json::json!(ocp.cost(states, controls)?), serde_json::Value::Null)
        } else {
            (serde_json::json!(report.cost), serde_json::json!(report.kkt))
        };
        serde_json::json!({
            "mode": if rti { "real-time step" } else { "scene controller" },
            "optimum": report.status == "Solved",
            "real_time_iteration": rti,
            "cost": cost,
            "kkt": kkt,
            "kkt_before_step": if rti { serde_json::json!(report.kkt) } else { serde_json::Value::Null },
            "status": report.status,
            "strategy": report.strategy,
            "iterations": report.iterations,
            "solve_time_s": report.solve_time,
            "first_control": report.u,
            "controls": rows(controls),
        })
    };
    let mut out = head;
    if let (Some(m), Some(f)) = (out.as_object_mut(), fields.as_object()) {
        for (k, x) in f {
            m.insert(k.clone(), x.clone());
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn omega_lists_and_ranges() {
        assert_eq!(parse_omegas("0.5,1,2").unwrap(), vec![0.5, 1.0, 2.0]);
        assert_eq!(
            parse_omegas("0.25:2.0:0.25").unwrap(),
            vec![0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0]
        );
        assert_eq!(parse_omegas("0.1:0.3:0.1").unwrap(), vec![0.1, 0.2, 0.3]);
        for bad in ["", "a", "1:0:0.5", "0:1:0", "0:1", "1,nan"] {
            assert!(parse_omegas(bad).is_err(), "{bad} accepted");
        }
    }
}
