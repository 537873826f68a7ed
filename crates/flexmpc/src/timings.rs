//! Measured timings — each sample's solve time and the loop's wall time — kept apart from
//! every other output, so that two runs of the same scene give identical files.
//!
//! Every file a closed loop writes is a pure function of its inputs (scene, options, flexmpc
//! version), except the timing files [`FILES`]: `timings.json`, `timings.csv` and
//! `solve_times.svg`. `--no-timings` leaves them out (and removes stale ones from the output
//! folder), so two whole output folders are byte-identical. The report `index.html` links to
//! the timing files but never embeds a measured number.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use mpc::RunResult;
use serde_json::{json, Map, Value};

use crate::plot::{self, Axes, Series};
use crate::results::SweepRun;

/// The real-time goal for the worst sample's solve time (s): 4× under τs = 0.2 s.
pub const SOLVE_TIME_GOAL_S: f64 = 0.05;

/// The files that hold measured timings (everything else is reproducible).
pub const FILES: [&str; 3] = ["timings.json", "timings.csv", "solve_times.svg"];

/// Keys of the summary (and of `summary_json`) that hold measured timings (and the thread
/// count they were measured on, which `--threads` sets).
pub const SUMMARY_KEYS: [&str; 8] = [
    "solve_time_worst_s",
    "solve_time_median_s",
    "wall_time_s",
    "solve_threads",
    "solve_cpu_per_thread_worst_s",
    "solve_cpu_per_thread_median_s",
    "solve_wall_worst_s",
    "solve_wall_median_s",
];

/// Keys of a per-sample report that hold its measured solve times ([`mpc::SampleReport`]'s
/// `solve_time` and [`mpc::SolveTiming`]) and its work counts (reproducible when the
/// intervals run serially, but a parallel line-search trial that fails stops after a number
/// of intervals that depends on the threads' timing).
pub const SAMPLE_KEYS: [&str; 6] = [
    "solve_time",
    "solve_cpu_all_threads",
    "solve_wall_time",
    "solve_threads",
    "solve_cpu_per_thread",
    "evaluations",
];

/// A sample time rounded to 1 ns, so that `0.6000000000000001` prints as `0.6`.
fn round_t(t: f64) -> f64 {
    (t * 1e9).round() / 1e9
}

/// Removes `keys` from a JSON object (no-op on other values).
fn strip(v: &mut Value, keys: &[&str]) {
    if let Value::Object(m) = v {
        for k in keys {
            m.remove(*k);
        }
    }
}

/// The summary of a run for `summary.json` / `sweep.json`: the summary keys, strategy counts
/// and errors, the number of samples — and no measured time.
pub fn summary_without_timings(r: &RunResult) -> Value {
    let r = r.without_timings();
    let mut v = serde_json::to_value(&r.summary).unwrap_or(Value::Null);
    strip(&mut v, &SUMMARY_KEYS);
    if let Value::Object(m) = &mut v {
        m.insert("samples".into(), json!(r.samples.len()));
    }
    v
}

/// The per-sample solver log for `samples.json`: status, strategy, iterations, cost, KKT
/// residual, applied control — without the solve time.
pub fn samples_without_timings(r: &RunResult) -> Value {
    let r = r.without_timings();
    let mut v = serde_json::to_value(&r.samples).unwrap_or(Value::Null);
    if let Value::Array(a) = &mut v {
        for s in a {
            strip(s, &SAMPLE_KEYS);
        }
    }
    v
}

/// The measured timings of one run: wall time, median and worst solve time in each measure,
/// and each sample's `(t, solve_time_s, cpu_all_threads_s, cpu_per_thread_s, wall_s,
/// iterations)` with its work counts.
pub fn run_json(r: &RunResult) -> Value {
    let s = &r.summary;
    let samples: Vec<Value> = r
        .samples
        .iter()
        .map(|x| {
            json!({
                "t": round_t(x.t),
                "solve_time_s": x.solve_time,
                "cpu_all_threads_s": x.timing.solve_cpu_all_threads,
                "cpu_per_thread_s": x.timing.solve_cpu_per_thread,
                "wall_s": x.timing.solve_wall_time,
                "iterations": x.iterations,
                "rhs_evaluations": x.evaluations.rhs,
                "jacobian_evaluations": x.evaluations.jacobians,
                "factorisations": x.evaluations.factorisations,
            })
        })
        .collect();
    json!({
        "controller": s.controller,
        "plant": s.plant,
        "omega0": s.omega0,
        "wall_time_s": r.wall_time_s,
        "solve_time_median_s": s.solve_time_median_s,
        "solve_time_worst_s": s.solve_time_worst_s,
        "solve_threads": s.solve_threads,
        "solve_cpu_per_thread_median_s": s.solve_cpu_per_thread_median_s,
        "solve_cpu_per_thread_worst_s": s.solve_cpu_per_thread_worst_s,
        "solve_wall_median_s": s.solve_wall_median_s,
        "solve_wall_worst_s": s.solve_wall_worst_s,
        "samples": samples,
    })
}

fn header(sampling: f64) -> Map<String, Value> {
    let mut m = Map::new();
    m.insert(
        "note".into(),
        json!(
            "measured times: they differ from run to run (every other output file is \
               reproducible). Per sample, for the whole solve, all attempts included: \
               solve_time_s is the CPU time of the calling thread (all of the solve's CPU when \
               solve_threads = 1); cpu_all_threads_s the CPU time of every thread of the \
               process (with parallel_intervals the rayon pool's idle spinning counts, and in \
               a sweep the runs going on at the same time); cpu_per_thread_s is \
               cpu_all_threads_s / solve_threads when the intervals run in parallel, else \
               solve_time_s; wall_s the wall-clock time. The plot shows cpu_per_thread_s. \
               rhs_evaluations, jacobian_evaluations and factorisations count the sample's \
               model evaluations and Newton-matrix factorisations: its work in units that are \
               the same on any machine."
        ),
    );
    m.insert("sampling_s".into(), json!(sampling));
    m.insert("goal_worst_solve_time_s".into(), json!(SOLVE_TIME_GOAL_S));
    m
}

fn create(path: &Path) -> Result<std::io::BufWriter<std::fs::File>> {
    Ok(std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    ))
}

/// The axes of a solve-time plot: log scale, dashed lines at `τs` and at the 50 ms goal.
fn solve_axes(title: String, sampling: f64) -> Axes {
    Axes {
        title,
        x: "t (s)".into(),
        y: "solve time (s)".into(),
        log_y: true,
        references: vec![
            (sampling, format!("τs = {sampling} s")),
            (SOLVE_TIME_GOAL_S, format!("goal {} ms", SOLVE_TIME_GOAL_S * 1e3)),
        ],
        points: false,
    }
}

/// Each sample's CPU time per thread ([`mpc::SolveTiming::solve_cpu_per_thread`]: the
/// calling thread's CPU unless the intervals run in parallel).
fn solve_series(r: &RunResult) -> Vec<(f64, f64)> {
    r.samples.iter().map(|s| (s.t, s.timing.solve_cpu_per_thread)).collect()
}

/// `flexmpc mpc`: writes `timings.json`, `timings.csv` (`t, solve_time_s, iterations,
/// cpu_all_threads_s, cpu_per_thread_s, wall_s` and the work counts `rhs_evaluations,
/// jacobian_evaluations, factorisations` per sample) and `solve_times.svg` (solve time per sample against `τs` and the 50 ms goal) into
/// `out`; returns their paths.
pub fn write_run(r: &RunResult, sampling: f64, out: &Path) -> Result<Vec<PathBuf>> {
    let mut v = header(sampling);
    if let Value::Object(run) = run_json(r) {
        v.extend(run);
    }
    let json_path = out.join(FILES[0]);
    std::fs::write(&json_path, serde_json::to_string_pretty(&Value::Object(v))?)
        .with_context(|| format!("writing {}", json_path.display()))?;
    let csv_path = out.join(FILES[1]);
    let mut f = create(&csv_path)?;
    writeln!(
        f,
        "t,solve_time_s,iterations,cpu_all_threads_s,cpu_per_thread_s,wall_s,rhs_evaluations,\
         jacobian_evaluations,factorisations"
    )?;
    for s in &r.samples {
        writeln!(
            f,
            "{},{:.6e},{},{:.6e},{:.6e},{:.6e},{},{},{}",
            round_t(s.t),
            s.solve_time,
            s.iterations,
            s.timing.solve_cpu_all_threads,
            s.timing.solve_cpu_per_thread,
            s.timing.solve_wall_time,
            s.evaluations.rhs,
            s.evaluations.jacobians,
            s.evaluations.factorisations
        )?;
    }
    f.flush()?;
    let svg = out.join(FILES[2]);
    plot::lines(
        &svg,
        (1000, 420),
        &solve_axes(
            format!("solve time per sample, {}", r.summary.controller.to_uppercase()),
            sampling,
        ),
        &[("solve time".into(), solve_series(r))],
    )?;
    Ok(vec![json_path, csv_path, svg])
}

/// `flexmpc sweep`: writes `timings.json` (every run's [`run_json`], in the sweep's order),
/// `timings.csv` (one row per run: `controller, plant, omega0, wall_time_s,
/// solve_time_median_s, solve_time_worst_s`) and `solve_times.svg` (one panel per controller,
/// one curve per ω0, against `τs` and the 50 ms goal) into `out`; returns their paths.
pub fn write_sweep(runs: &[SweepRun], sampling: f64, out: &Path) -> Result<Vec<PathBuf>> {
    let mut v = header(sampling);
    let list: Vec<Value> = runs
        .iter()
        .map(|r| match &r.result {
            Ok(res) => run_json(res),
            Err(e) => json!({ "controller": r.controller.name(), "omega0": r.omega0, "error": e }),
        })
        .collect();
    v.insert("runs".into(), Value::Array(list));
    let json_path = out.join(FILES[0]);
    std::fs::write(&json_path, serde_json::to_string_pretty(&Value::Object(v))?)
        .with_context(|| format!("writing {}", json_path.display()))?;
    let csv_path = out.join(FILES[1]);
    let mut f = create(&csv_path)?;
    writeln!(f, "controller,plant,omega0,wall_time_s,solve_time_median_s,solve_time_worst_s")?;
    for r in runs {
        if let Ok(res) = &r.result {
            let s = &res.summary;
            writeln!(
                f,
                "{},{},{},{:.6e},{:.6e},{:.6e}",
                r.label(),
                s.plant,
                s.omega0,
                res.wall_time_s,
                s.solve_time_median_s,
                s.solve_time_worst_s
            )?;
        }
    }
    f.flush()?;
    let svg = out.join(FILES[2]);
    let charts: Vec<(Axes, Vec<Series>)> = crate::results::sweep_kinds(runs)
        .into_iter()
        .map(|k| {
            let series = runs
                .iter()
                .filter(|r| r.controller == k)
                .filter_map(|r| r.result.as_ref().ok())
                .map(|res| (format!("ω0 = {}", res.summary.omega0), solve_series(res)))
                .collect();
            (
                solve_axes(format!("solve time per sample, {}", k.name().to_uppercase()), sampling),
                series,
            )
        })
        .collect();
    plot::panels(&svg, (620 * charts.len().max(1) as u32, 460), &charts)?;
    Ok(vec![json_path, csv_path, svg])
}

/// `--no-timings`: removes timing files a previous run left in `out`.
pub fn remove(out: &Path) -> Result<()> {
    for f in FILES {
        let p = out.join(f);
        match std::fs::remove_file(&p) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e).with_context(|| format!("removing {}", p.display())),
        }
    }
    Ok(())
}
