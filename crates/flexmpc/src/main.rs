//! `flexmpc`: the command-line front end — scene files, simulations, modes, MPC closed loops,
//! sweeps, reports.
//!
//! Without arguments it runs the built-in default scene, the paper's 2D NMPC example
//! (`scenes/paper-2d-mpc.toml`), and writes its report to `out/paper-2d-mpc/index.html`.
//! `flexmpc mpc <scene.toml>` runs one closed loop (CSV, per-sample solver log, report),
//! `flexmpc sweep <scene.toml>` runs ω0 × controllers in parallel (table, Fig. 6-style plot),
//! `flexmpc ocp <scene.toml>` solves (and `--export`s) the first sample's problem alone,
//! `flexmpc simulate <scene.toml>` runs the uncontrolled FE plant, `flexmpc modes` lists and
//! plots the constrained modes, `flexmpc check` validates a scene. Global flags: `--quiet`
//! (no progress, no extra prints), `--json` (machine-readable summary on stdout),
//! `--threads N` (rayon pool), `--no-timings` (no measured-time files: the outputs of two runs
//! are byte-identical; without it only `timings.*` and `solve_times.svg` differ).

use flexmpc::control::{self, Overrides};
use flexmpc::{modes, run, scene};

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use clap::{Parser, Subcommand};

use flexmpc::{DEFAULT_SCENE, DEFAULT_SCENE_PATH};

#[derive(Parser)]
#[command(
    name = "flexmpc",
    version,
    about = "Simulation and control of very flexible multibody structures",
    long_about = "Simulation and control of very flexible multibody structures.\n\nWithout a \
                  command, runs the paper's 2D NMPC example (scenes/paper-2d-mpc.toml, built \
                  in) and writes its report to out/paper-2d-mpc/index.html."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// No progress bars and no informational output (errors still go to stderr).
    #[arg(long, global = true)]
    quiet: bool,
    /// Print a machine-readable JSON summary on stdout (and nothing else there).
    #[arg(long, global = true)]
    json: bool,
    /// Worker threads of the parallel runs (rayon pool; default: one per core).
    #[arg(long, global = true)]
    threads: Option<usize>,
    /// Leave the measured timings out (`mpc`, `sweep`, `ocp`, default run): no
    /// `timings.json`, `timings.csv`, `solve_times.svg` (stale ones are removed) and, for
    /// `ocp`, no `solve_time_s`; two runs of the same inputs then write byte-identical files.
    #[arg(long, global = true)]
    no_timings: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene's uncontrolled FE plant and write its time series (CSV) to an output folder.
    Simulate {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Output folder (default `out/<scene name>`).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Simulated time (s; default: `[run] duration`).
        #[arg(long)]
        duration: Option<f64>,
    },
    /// Constrained linear modes of a scene's structure: frequencies, labels, plots.
    Modes {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Reference angle (degrees) of the structure's first joint (default: the scene's
        /// `[modes] angles`, else its `attach` angle).
        #[arg(long, allow_hyphen_values = true)]
        angle: Option<f64>,
        /// Number of modes, rigid ones included (default: `[modes] count`, else 8).
        #[arg(long)]
        modes: Option<usize>,
        /// Output folder for the plots (default `out/<scene name>/modes`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Validate a scene file without running it.
    Check {
        /// Scene file (TOML).
        scene: PathBuf,
    },
    /// One MPC closed loop of a scene's `[scenario]`: CSV, solver log, HTML report.
    Mpc {
        /// Scene file (TOML) with `[scenario]`.
        scene: PathBuf,
        /// Controller (default: `[controller] kind`).
        #[arg(long, value_parser = ["nmpc", "lmpc"])]
        controller: Option<String>,
        /// Plant (default: `[scenario] plant`).
        #[arg(long, value_parser = ["fe", "rom"])]
        plant: Option<String>,
        /// Disturbance ω0 (rad/s; default: `[scenario] omega0`).
        #[arg(long, allow_hyphen_values = true)]
        omega0: Option<f64>,
        /// Duration of the loop (s; default: `[scenario] duration`).
        #[arg(long)]
        duration: Option<f64>,
        /// Output folder (default `out/<scene name>`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// The first sample's optimal control problem alone: optimal cost, controls, iterations,
    /// solve time; `--export DIR` also writes the whole problem for other solvers.
    Ocp {
        /// Scene file (TOML) with `[scenario]`.
        scene: PathBuf,
        /// Controller (default: `[controller] kind`).
        #[arg(long, value_parser = ["nmpc", "lmpc"])]
        controller: Option<String>,
        /// Disturbance ω0 (rad/s; default: `[scenario] omega0`).
        #[arg(long, allow_hyphen_values = true)]
        omega0: Option<f64>,
        /// Write the modal model and `ocp.json` of the problem to this folder.
        #[arg(long)]
        export: Option<PathBuf>,
        /// Solve the problem to convergence (full SQP, KKT tolerance 1e-8, no fallback),
        /// whatever the scene's real-time settings.
        #[arg(long)]
        converge: bool,
    },
    /// Closed loops for several ω0 and controllers in parallel: table and Fig. 6-style plot.
    Sweep {
        /// Scene file (TOML) with `[scenario]` (and usually `[sweep]`).
        scene: PathBuf,
        /// ω0 values: a list `0.5,1,2` or a range `0.25:2.0:0.25` (default: `[sweep] omega0`).
        #[arg(long)]
        omega0: Option<String>,
        /// Controllers, comma-separated `nmpc,lmpc` (default: `[sweep] controllers`).
        #[arg(long)]
        controller: Option<String>,
        /// Plant (default: `[scenario] plant`).
        #[arg(long, value_parser = ["fe", "rom"])]
        plant: Option<String>,
        /// Duration of each loop (s; default: `[scenario] duration`).
        #[arg(long)]
        duration: Option<f64>,
        /// Output folder (default `out/<scene name>/sweep`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

fn default_out(scene: &Path) -> PathBuf {
    let stem = scene
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "scene".into());
    PathBuf::from("out").join(stem)
}

/// How runs write their files.
fn output_options(cli: &Cli) -> control::OutputOptions {
    control::OutputOptions { quiet: cli.quiet, timings: !cli.no_timings }
}

/// Whether human-readable lines go to stdout.
fn chatty(cli: &Cli) -> bool {
    !cli.quiet && !cli.json
}

fn print_simulation(summary: &run::RunSummary, cli: &Cli) -> Result<()> {
    if cli.json {
        let v = serde_json::json!({
            "steps": summary.steps,
            "seconds": summary.seconds,
            "total_energy_start": summary.total_energy.0,
            "total_energy_end": summary.total_energy.1,
            "velocity_violation": summary.velocity_violation,
            "csv": summary.csv,
            "plot": summary.plot,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else if chatty(cli) {
        println!(
            "{} steps in {:.2} s; energy + potential {:.6e} → {:.6e}; max velocity-constraint \
             violation {:.1e}; wrote {}",
            summary.steps,
            summary.seconds,
            summary.total_energy.0,
            summary.total_energy.1,
            summary.velocity_violation,
            summary.csv.display()
        );
        if let Some(p) = &summary.plot {
            println!("plot: {}", p.display());
        }
    }
    Ok(())
}

fn print_mpc(o: &control::MpcOutput, cli: &Cli) -> Result<()> {
    if cli.json {
        println!("{}", serde_json::to_string_pretty(&control::summary_json(&o.result))?);
        return Ok(());
    }
    if !chatty(cli) {
        return Ok(());
    }
    let s = &o.result.summary;
    println!(
        "{} on the {} plant, ω0 = {}: {} — V(T)/V(0) = {:.3e}, largest joint angle {:.1}°, \
         orientation error {:.2}° (largest {:.1}°), rigid rate ratio {:.2e}",
        s.controller.to_uppercase(),
        s.plant,
        s.omega0,
        if s.stabilised { "stabilised" } else { "NOT stabilised" },
        s.v_ratio_final,
        s.max_joint_angle_deg,
        s.orientation_error_deg,
        s.max_orientation_deg,
        s.rigid_rate_ratio
    );
    println!(
        "{} samples: solve time median {:.3} s, worst {:.3} s (τs = {} s); relaxed {}, LMPC \
         fallback {} (then held {}; plans beyond the joint limit in {}); loop wall time {:.1} s{}",
        o.result.samples.len(),
        s.solve_time_median_s,
        s.solve_time_worst_s,
        o.control.scenario.mpc.sampling,
        s.relaxed_samples,
        s.fallback_samples,
        s.held_samples,
        s.joint_limit_samples,
        o.result.wall_time_s,
        s.error.as_ref().map(|e| format!("; stopped at {} s: {e}", s.t_end)).unwrap_or_default()
    );
    println!(
        "wrote {}, {}, {}; report: {}",
        o.csv.display(),
        o.samples.display(),
        o.summary.display(),
        o.report.display()
    );
    if o.timings.is_empty() {
        println!("timings not written (--no-timings)");
    } else {
        let t: Vec<String> = o.timings.iter().map(|p| p.display().to_string()).collect();
        println!("measured timings: {}", t.join(", "));
    }
    Ok(())
}

fn kind_of(name: Option<&str>) -> Result<Option<mpc::ControllerKind>> {
    match name {
        None => Ok(None),
        Some(n) => match scene::controller_kind(n) {
            Some(k) => Ok(Some(k)),
            None => bail!("--controller `{n}` (allowed: nmpc, lmpc)"),
        },
    }
}

fn plant_of(name: Option<&str>) -> Result<Option<mpc::PlantKind>> {
    match name {
        None => Ok(None),
        Some(n) => match scene::plant_kind(n) {
            Some(k) => Ok(Some(k)),
            None => bail!("--plant `{n}` (allowed: fe, rom)"),
        },
    }
}

fn modes_json(report: &modal_rom::ModeReport) -> serde_json::Value {
    serde_json::json!({
        "frequencies_rad_s": report.frequencies_rad_s,
        "labels": report.labels,
        "n_rigid": report.n_rigid,
    })
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    // faer's dense kernels (eigen, SVD, QR, products in modal-rom / intrinsic-beam) would
    // otherwise split their work over the rayon pool, so their rounding, and a chaotic closed
    // loop's whole trajectory, would depend on `--threads`; the runs of a sweep are what runs
    // in parallel here
    faer::set_global_parallelism(faer::Par::Seq);
    if let Some(n) = cli.threads {
        if n == 0 {
            bail!("--threads must be at least 1, got 0");
        }
        rayon::ThreadPoolBuilder::new().num_threads(n).build_global()?;
    }
    match &cli.command {
        Some(Command::Simulate { scene, out, duration }) => {
            let mut s = scene::load(scene)?;
            if let Some(d) = *duration {
                if !(d.is_finite() && d > 0.0) {
                    bail!("--duration must be finite and > 0, got {d}");
                }
                s.steps = (d / s.plant.settings().dt).round().max(1.0) as usize;
            }
            let out = out.clone().unwrap_or_else(|| default_out(scene));
            let summary = run::simulate(s, &out, cli.quiet || cli.json)?;
            print_simulation(&summary, &cli)?;
        }
        Some(Command::Modes { scene, angle, modes: n_modes, out }) => {
            let base = scene::load(scene)?;
            let n_modes = n_modes.unwrap_or(base.mode_count);
            if n_modes == 0 {
                bail!("--modes must be at least 1, got 0");
            }
            let angles: Vec<Option<f64>> = match angle {
                Some(a) => vec![Some(*a)],
                None if !base.mode_angles.is_empty() => {
                    base.mode_angles.iter().map(|a| Some(*a)).collect()
                }
                None => vec![None],
            };
            let dir = out.clone().unwrap_or_else(|| default_out(scene).join("modes"));
            let mut all = Vec::new();
            for a in &angles {
                let (s, dir) = match a {
                    Some(a) if angles.len() > 1 => {
                        (scene::load_at_angle(scene, *a)?, dir.join(format!("angle-{a}")))
                    }
                    Some(a) => (scene::load_at_angle(scene, *a)?, dir.clone()),
                    None => (scene::load(scene)?, dir.clone()),
                };
                let report = modes::report(s.plant.structure(), n_modes)?;
                let figures = modes::plot(&report, &dir)?;
                if !cli.json {
                    if angles.len() > 1 && !cli.quiet {
                        println!("reference angle {}°:", a.unwrap_or(0.0));
                    }
                    if !cli.quiet {
                        modes::print_table(&report);
                        for f in figures {
                            println!("plot: {}", f.display());
                        }
                    }
                }
                all.push((*a, report));
            }
            if cli.json {
                let v = if all.len() == 1 {
                    modes_json(&all[0].1)
                } else {
                    serde_json::json!({
                        "angles": all
                            .iter()
                            .map(|(a, r)| {
                                let mut v = modes_json(r);
                                v["angle_deg"] = serde_json::json!(a);
                                v
                            })
                            .collect::<Vec<_>>()
                    })
                };
                println!("{}", serde_json::to_string_pretty(&v)?);
            }
        }
        Some(Command::Check { scene }) => {
            let s = scene::load(scene)?;
            let st = s.plant.structure();
            if cli.json {
                let v = serde_json::json!({
                    "scene": scene,
                    "ok": true,
                    "beams": st.beams().len(),
                    "joints": st.joints().len(),
                    "unknowns": st.dim(),
                    "steps": s.steps,
                    "controlled": s.control.is_some(),
                    "control_inputs": s.control.as_ref().map_or(0, |c| c.scenario.inputs.len()),
                });
                println!("{}", serde_json::to_string_pretty(&v)?);
            } else if !cli.quiet {
                println!(
                    "{}: ok ({} beams, {} joints/supports, {} unknowns, {} steps{})",
                    scene.display(),
                    st.beams().len(),
                    st.joints().len(),
                    st.dim(),
                    s.steps,
                    match &s.control {
                        Some(c) => format!(
                            "; closed loop: {} inputs, {} on the {} plant, ω0 = {}",
                            c.scenario.inputs.len(),
                            c.controller.kind.name(),
                            c.plant.name(),
                            c.omega0
                        ),
                        None => String::new(),
                    }
                );
            }
        }
        Some(Command::Mpc { scene, controller, plant, omega0, duration, out }) => {
            let s = scene::load(scene)?;
            let ov = Overrides {
                controller: kind_of(controller.as_deref())?,
                plant: plant_of(plant.as_deref())?,
                omega0: *omega0,
                duration: *duration,
            };
            let out = out.clone().unwrap_or_else(|| default_out(scene));
            let o = control::run_mpc(&s, &ov, &out, output_options(&cli))?;
            print_mpc(&o, &cli)?;
        }
        Some(Command::Ocp { scene, controller, omega0, export, converge }) => {
            let s = scene::load(scene)?;
            let ov = Overrides {
                controller: kind_of(controller.as_deref())?,
                omega0: *omega0,
                ..Default::default()
            };
            let mut v = control::first_sample(&s, &ov, export.as_deref(), *converge)?;
            if cli.no_timings {
                if let Some(m) = v.as_object_mut() {
                    m.remove("solve_time_s");
                }
            }
            if cli.json {
                println!("{}", serde_json::to_string_pretty(&v)?);
            } else if !cli.quiet {
                println!(
                    "{} first sample, ω0 = {} ({}): cost {:.6e}, KKT {}, {} iterations, {}, status {} ({})",
                    v["controller"].as_str().unwrap_or("?").to_uppercase(),
                    v["omega0"],
                    v["mode"].as_str().unwrap_or("?"),
                    v["cost"].as_f64().unwrap_or(f64::NAN),
                    v["kkt"].as_f64().map_or_else(
                        || "not evaluated after the step".to_string(),
                        |k| format!("{k:.1e}")
                    ),
                    v["iterations"],
                    v["solve_time_s"]
                        .as_f64()
                        .map_or_else(|| "time not shown".to_string(), |t| format!("{t:.3} s")),
                    v["status"].as_str().unwrap_or("?"),
                    v["strategy"].as_str().unwrap_or("?")
                );
                if let Some(c) = v["controls"].as_array() {
                    println!("u over the horizon ({} intervals, inputs {}):", c.len(), v["inputs"]);
                    for (k, u) in c.iter().enumerate() {
                        println!("{k:>4} {u}");
                    }
                }
                if let Some(d) = export {
                    println!("exported the problem to {}", d.display());
                }
            }
        }
        Some(Command::Sweep { scene, omega0, controller, plant, duration, out }) => {
            let s = scene::load(scene)?;
            let Some(c) = &s.control else {
                bail!("{}: no [scenario] section (see scenes/paper-2d-mpc.toml)", scene.display());
            };
            let omegas = match omega0 {
                Some(t) => control::parse_omegas(t)?,
                None if !c.sweep_omegas.is_empty() => c.sweep_omegas.clone(),
                None => bail!(
                    "{}: no ω0 to sweep: give --omega0 0.25:2.0:0.25 or a [sweep] section",
                    scene.display()
                ),
            };
            let kinds = match controller {
                Some(list) => list
                    .split(',')
                    .map(|k| kind_of(Some(k.trim())).map(|k| k.expect("some")))
                    .collect::<Result<Vec<_>>>()?,
                None => c.sweep_controllers.clone(),
            };
            let ov = Overrides {
                controller: None,
                plant: plant_of(plant.as_deref())?,
                omega0: None,
                duration: *duration,
            };
            let out = out.clone().unwrap_or_else(|| default_out(scene).join("sweep"));
            let o = control::run_sweep(&s, &ov, &omegas, &kinds, &out, output_options(&cli))?;
            if cli.json {
                let v: Vec<serde_json::Value> = o
                    .runs
                    .iter()
                    .map(|r| match &r.result {
                        Ok(res) => control::summary_json(res),
                        Err(e) => serde_json::json!({
                            "omega0": r.omega0, "controller": r.controller.name(),
                            "stabilised": false, "error": e,
                        }),
                    })
                    .collect();
                println!("{}", serde_json::to_string_pretty(&v)?);
            } else if !cli.quiet {
                println!(
                    "{:>5} {:>6} {:>11} {:>9} {:>12} {:>11} {:>8} {:>8}  stabilised",
                    "ctrl",
                    "ω0",
                    "V(T)/V(0)",
                    "joint°",
                    "orient° err",
                    "rigid rate",
                    "relaxed",
                    "fallback"
                );
                for r in &o.runs {
                    match &r.result {
                        Ok(res) => {
                            let s = &res.summary;
                            println!(
                                "{:>5} {:>6} {:>11.3e} {:>9.1} {:>12.2} {:>11.2e} {:>8} {:>8}  {}{}",
                                s.controller,
                                s.omega0,
                                s.v_ratio_final,
                                s.max_joint_angle_deg,
                                s.orientation_error_deg,
                                s.rigid_rate_ratio,
                                s.relaxed_samples,
                                s.fallback_samples,
                                if s.stabilised { "yes" } else { "no" },
                                s.error
                                    .as_ref()
                                    .map(|e| format!(" (stopped at {} s: {e})", s.t_end))
                                    .unwrap_or_default()
                            );
                        }
                        Err(e) => {
                            println!("{:>5} {:>6} failed: {e}", r.controller.name(), r.omega0)
                        }
                    }
                }
                println!(
                    "wrote {}, {}, {} (V(t)/V(0) per ω0), {}, runs/*.csv, runs/*-snapshots.svg",
                    o.csv.display(),
                    o.json.display(),
                    o.plot.display(),
                    o.figures
                        .iter()
                        .map(|p| p.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                if o.timings.is_empty() {
                    println!("timings not written (--no-timings)");
                } else {
                    let t: Vec<String> =
                        o.timings.iter().map(|p| p.display().to_string()).collect();
                    println!("measured timings: {}", t.join(", "));
                }
                println!("report: {}", o.report.display());
            }
        }
        None => {
            let path = Path::new(DEFAULT_SCENE_PATH);
            let s = scene::load_str(path, DEFAULT_SCENE)?;
            let out = default_out(path);
            if chatty(&cli) {
                println!(
                    "flexmpc {}: running the default scene {} ({}) — the paper's 2D NMPC example",
                    env!("CARGO_PKG_VERSION"),
                    path.display(),
                    s.description.trim()
                );
            }
            let o = control::run_mpc(&s, &Overrides::default(), &out, output_options(&cli))?;
            print_mpc(&o, &cli)?;
            if chatty(&cli) {
                println!(
                    "open {} in a browser; `flexmpc --help` lists the commands (mpc, sweep, ocp, \
                     simulate, modes, check)",
                    o.report.display()
                );
            }
        }
    }
    Ok(())
}
