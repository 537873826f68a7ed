//! `flexmpc`: the command-line front end — scene files, simulations, modes, MPC closed loops,
//! sweeps, reports.
//!
//! Without arguments it runs the built-in default scene, the paper's 2D NMPC example
//! (`scenes/paper-2d-mpc.toml`), and writes its report to
//! `out/paper-2d-mpc/nmpc-fe-w1/index.html`. Every closed loop writes to its own folder
//! `out/<scene>/<controller>-<plant>-w<ω0>/` (or `--out DIR`), so runs of other variants never
//! overwrite each other.
//! `flexmpc mpc <scene.toml>` runs one closed loop (CSV, per-sample solver log, report),
//! `flexmpc sweep <scene.toml>` runs ω0 × controllers in parallel (table, Fig. 6-style plot),
//! `flexmpc ocp <scene.toml>` solves (and `--export`s) the first sample's problem alone,
//! `flexmpc simulate <scene.toml>` runs the uncontrolled FE plant, `flexmpc modes` lists and
//! plots the constrained modes, `flexmpc check` validates a scene. Global flags: `--quiet`
//! (no progress, no extra prints), `--json` (machine-readable summary on stdout),
//! `--threads N` (rayon pool), `--no-timings` (no measured-time files: the outputs of two runs
//! are byte-identical; without it only `timings.*` and `solve_times.svg` differ), `--out DIR`.
//!
//! Errors: a mistake in the input (scene, option, file) prints `error: …` and its causes, one
//! line each, whatever `RUST_BACKTRACE` says, and exits with 1; an internal error (a panic)
//! says that it is a bug and how to report it ([`flexmpc::bug_report`]) and exits with 101. A closed stdout (`flexmpc … | head -1`) ends
//! the run quietly.

use flexmpc::control::{self, Overrides};
use flexmpc::{modes, run, scene};

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

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
                  in) and writes its report to out/paper-2d-mpc/nmpc-fe-w1/index.html."
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
    /// Worker threads of the parallel runs, and with `[controller] parallel_intervals` of
    /// each solve's shooting intervals (rayon pool; default: one per core; the results do not
    /// depend on it).
    #[arg(long, global = true)]
    threads: Option<usize>,
    /// Leave the measured timings out (`mpc`, `sweep`, `ocp`, default run): no
    /// `timings.json`, `timings.csv`, `solve_times.svg` (stale ones are removed) and, for
    /// `ocp`, no `solve_time_s`; two runs of the same inputs then write byte-identical files.
    #[arg(long, global = true)]
    no_timings: bool,
    /// Output folder (default: `out/<scene>/<controller>-<plant>-w<ω0>/` for `mpc` and the
    /// default run, `out/<scene>/sweep-<controllers>-<plant>-w<ω0 list>/` for `sweep`,
    /// `out/<scene>/simulate/` and `out/<scene>/modes/`).
    #[arg(long, global = true)]
    out: Option<PathBuf>,
    /// Also write the deformed structure over time as VTK files for ParaView (`mpc`,
    /// `simulate`, default run): `vtk/<name>-<step>.vtu` and the collection `vtk/<name>.pvd`.
    #[arg(long, global = true)]
    vtk: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene's uncontrolled FE plant and write its time series (CSV) to an output folder.
    Simulate {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Simulated time (s; default: `[run] duration`).
        #[arg(long)]
        duration: Option<f64>,
        /// Plant: the FE model (default) or the reduced model (`rom`, open loop, same CSV
        /// columns; out/<scene>/simulate-rom-<model>/).
        #[arg(long, value_parser = ["fe", "rom"])]
        plant: Option<String>,
        /// Reduced model of `--plant rom` (default: `[controller] model`, else paper).
        #[arg(long, value_parser = ["paper", "exact-joints"])]
        model: Option<String>,
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
        /// Controller's reduced model (default: `[controller] model`).
        #[arg(long, value_parser = ["paper", "exact-joints"])]
        model: Option<String>,
        /// Plant (default: `[scenario] plant`).
        #[arg(long, value_parser = ["fe", "rom"])]
        plant: Option<String>,
        /// Disturbance ω0 (rad/s; default: `[scenario] omega0`).
        #[arg(long, allow_hyphen_values = true)]
        omega0: Option<f64>,
        /// Duration of the loop (s; default: `[scenario] duration`).
        #[arg(long)]
        duration: Option<f64>,
        /// Run the loop N times and keep each sample's smallest measured solve time: the
        /// same work every time (the runs must agree apart from their timings), so the
        /// smallest is its cost without the interference of other processes (timings on a
        /// shared machine). Every other output is the first run's.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        repeat: u32,
    },
    /// The first sample's optimal control problem alone: optimal cost, controls, iterations,
    /// solve time; `--export DIR` also writes the whole problem for other solvers.
    Ocp {
        /// Scene file (TOML) with `[scenario]`.
        scene: PathBuf,
        /// Controller (default: `[controller] kind`).
        #[arg(long, value_parser = ["nmpc", "lmpc"])]
        controller: Option<String>,
        /// Controller's reduced model (default: `[controller] model`).
        #[arg(long, value_parser = ["paper", "exact-joints"])]
        model: Option<String>,
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
        /// Controller's reduced models, comma-separated `paper,exact-joints` (default:
        /// `[controller] model`); with two, both are drawn on the same axes (cost.svg).
        #[arg(long)]
        model: Option<String>,
        /// Plant (default: `[scenario] plant`).
        #[arg(long, value_parser = ["fe", "rom"])]
        plant: Option<String>,
        /// Duration of each loop (s; default: `[scenario] duration`).
        #[arg(long)]
        duration: Option<f64>,
    },
    /// Fails with an internal error on purpose: what a user sees on a bug (for tests).
    #[command(hide = true)]
    InternalErrorCheck,
}

/// Prints a line on stdout; a write error (a closed pipe) becomes an error of the run.
macro_rules! say {
    ($($arg:tt)*) => {
        writeln!(std::io::stdout().lock(), $($arg)*)?
    };
}

/// `out/<scene file stem>`, the folder of every output of a scene.
fn scene_out(scene: &Path) -> PathBuf {
    let stem = scene
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "scene".into());
    PathBuf::from("out").join(stem)
}

/// `""` for the paper's model, `-exact` for the exact-joints model: the folder names of runs
/// with other controller models differ.
fn model_tag(m: mpc::ModelKind) -> &'static str {
    match m {
        mpc::ModelKind::Paper => "",
        mpc::ModelKind::ExactJoints => "-exact",
    }
}

/// [`model_tag`] of one model; `-paper+exact-joints` (the names joined by `+`) for several.
fn models_tag(models: &[mpc::ModelKind]) -> String {
    match models {
        [m] => model_tag(*m).to_string(),
        _ => format!("-{}", models.iter().map(|m| m.name()).collect::<Vec<_>>().join("+")),
    }
}

/// The output folder of one closed loop: `--out`, else
/// `out/<scene>/<controller>[-exact]-<plant>-w<ω0>/` (`-exact`: the exact-joints model).
fn mpc_out(cli: &Cli, scene: &Path, c: &flexmpc::scene::Control) -> PathBuf {
    cli.out.clone().unwrap_or_else(|| {
        scene_out(scene).join(format!(
            "{}{}-{}-w{}",
            c.controller.kind.name(),
            model_tag(c.controller.model),
            c.plant.name(),
            c.omega0
        ))
    })
}

/// The output folder of a sweep: `--out`, else
/// `out/<scene>/sweep-<controllers joined by +>[<models tag>]-<plant>-w<ω0 joined by _>/` (more than eight
/// ω0: first, last, count and a hash of the list).
fn sweep_out(
    cli: &Cli,
    scene: &Path,
    kinds: &[mpc::ControllerKind],
    models: &[mpc::ModelKind],
    plant: mpc::PlantKind,
    omegas: &[f64],
) -> PathBuf {
    cli.out.clone().unwrap_or_else(|| {
        let ctrl: Vec<&str> = kinds.iter().map(|k| k.name()).collect();
        let w = if omegas.len() <= 8 {
            omegas.iter().map(|w| w.to_string()).collect::<Vec<_>>().join("_")
        } else {
            // FNV-1a of the values' bits: the same list, the same folder
            let mut h: u64 = 0xcbf2_9ce4_8422_2325;
            for b in omegas.iter().flat_map(|w| w.to_bits().to_le_bytes()) {
                h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
            }
            format!("{}-{}-n{}-{:08x}", omegas[0], omegas[omegas.len() - 1], omegas.len(), h as u32)
        };
        scene_out(scene).join(format!(
            "sweep-{}{}-{}-w{w}",
            ctrl.join("+"),
            models_tag(models),
            plant.name()
        ))
    })
}

/// With `--vtk`, writes the closed loop's snapshots as `vtk/mpc-<k>.vtu` and `vtk/mpc.pvd` into
/// its output folder.
fn write_vtk(cli: &Cli, s: &scene::Scene, o: &control::MpcOutput) -> Result<()> {
    if cli.vtk {
        let dir = o.report.parent().unwrap_or(Path::new(".")).join("vtk");
        let pvd = flexmpc::vtk::write(
            &dir,
            "mpc",
            &flexmpc::vtk::frames_of_snapshots(&o.result.snapshots, &s.structure),
        )?;
        if chatty(cli) {
            say!("ParaView: {}", pvd.display());
        }
    }
    Ok(())
}

/// Refuses a structure whose modal basis would not fit in memory (before anything dense is
/// allocated).
fn check_modal_size(s: &scene::Scene) -> Result<()> {
    modes::check_size(&s.structure)
        .map(|_| ())
        .map_err(|e| anyhow::anyhow!("{}: {e}", s.file.display()))
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
            "vtk": summary.vtk,
        });
        say!("{}", serde_json::to_string_pretty(&v)?);
    } else if chatty(cli) {
        say!(
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
            say!("plot: {}", p.display());
        }
        if let Some(p) = &summary.vtk {
            say!("ParaView: {}", p.display());
        }
    }
    Ok(())
}

fn print_mpc(o: &control::MpcOutput, cli: &Cli) -> Result<()> {
    if cli.json {
        say!("{}", serde_json::to_string_pretty(&control::summary_json(&o.result))?);
        return Ok(());
    }
    if !chatty(cli) {
        return Ok(());
    }
    let s = &o.result.summary;
    say!(
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
    // without the LMPC fallback a failed sample applies the NMPC's own last iterate
    let failed = if o.control.controller.fallback_to_lmpc {
        format!("LMPC fallback {}", s.fallback_samples)
    } else {
        format!("not accepted {} (the NMPC's own iterate applied)", s.fallback_samples)
    };
    // with the intervals in parallel the calling thread's CPU misses the pool's work
    let times = if o.control.controller.parallel_intervals {
        format!(
            "solve time (CPU per thread: all threads' CPU / {}) median {:.3} s, worst {:.3} s, \
             wall median {:.3} s, worst {:.3} s",
            s.solve_threads,
            s.solve_cpu_per_thread_median_s,
            s.solve_cpu_per_thread_worst_s,
            s.solve_wall_median_s,
            s.solve_wall_worst_s
        )
    } else {
        format!(
            "solve time (the thread's CPU) median {:.3} s, worst {:.3} s",
            s.solve_time_median_s, s.solve_time_worst_s
        )
    };
    say!(
        "{} samples: {} (τs = {} s); relaxed {}, {} \
         (then held {}; plans beyond the joint limit in {}); loop wall time {:.1} s{}",
        o.result.samples.len(),
        times,
        o.control.scenario.mpc.timing.sampling,
        s.relaxed_samples,
        failed,
        s.held_samples,
        s.joint_limit_samples,
        o.result.wall_time_s,
        s.error.as_ref().map(|e| format!("; stopped at {} s: {e}", s.t_end)).unwrap_or_default()
    );
    say!(
        "wrote {}, {}, {}; report: {}",
        o.csv.display(),
        o.samples.display(),
        o.summary.display(),
        o.report.display()
    );
    if o.timings.is_empty() {
        say!("timings not written (--no-timings)");
    } else {
        let t: Vec<String> = o.timings.iter().map(|p| p.display().to_string()).collect();
        say!("measured timings: {}", t.join(", "));
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

fn model_of(name: Option<&str>) -> Result<Option<mpc::ModelKind>> {
    match name {
        None => Ok(None),
        Some(n) => match scene::model_kind(n) {
            Some(m) => Ok(Some(m)),
            None => bail!("--model `{n}` (allowed: paper, exact-joints)"),
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

/// Whether `e` comes from writing to a closed stdout.
fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

fn main() -> ExitCode {
    flexmpc::bug_report::install_panic_hook();
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => ExitCode::SUCCESS,
        // the reader went away (`| head`): nothing more to say, and no one to say it to
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            let mut err = std::io::stderr().lock();
            let _ = writeln!(err, "error: {e}");
            for cause in e.chain().skip(1) {
                let _ = writeln!(err, "  caused by: {cause}");
            }
            ExitCode::FAILURE
        }
    }
}

fn run(cli: &Cli) -> Result<()> {
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
        Some(Command::Simulate { scene, duration, plant, model }) => {
            let mut s = scene::load(scene)?;
            if let Some(d) = *duration {
                if !(d.is_finite() && d > 0.0) {
                    bail!("--duration must be finite and > 0, got {d}");
                }
                s.steps = (d / s.plant_settings.dt).round().max(1.0) as usize;
            }
            let rom = plant_of(plant.as_deref())? == Some(mpc::PlantKind::Rom);
            let model = model_of(model.as_deref())?;
            if model.is_some() && !rom {
                bail!("--model selects the reduced model of `--plant rom`");
            }
            let model = model
                .or_else(|| s.control.as_ref().map(|c| c.controller.model))
                .unwrap_or_default();
            let sub =
                if rom { format!("simulate-rom-{}", model.name()) } else { "simulate".into() };
            let out = cli.out.clone().unwrap_or_else(|| scene_out(scene).join(sub));
            let quiet = cli.quiet || cli.json;
            let summary = if rom {
                run::simulate_model(s, &out, quiet, model)?
            } else {
                run::simulate_with(s, &out, quiet, cli.vtk)?
            };
            print_simulation(&summary, cli)?;
        }
        Some(Command::Modes { scene, angle, modes: n_modes }) => {
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
            modes::plan(&base.structure)
                .map_err(|e| anyhow::anyhow!("{}: {e}", base.file.display()))?;
            let dir = cli.out.clone().unwrap_or_else(|| scene_out(scene).join("modes"));
            let mut all = Vec::new();
            for a in &angles {
                let (s, dir) = match a {
                    Some(a) if angles.len() > 1 => {
                        (scene::load_at_angle(scene, *a)?, dir.join(format!("angle-{a}")))
                    }
                    Some(a) => (scene::load_at_angle(scene, *a)?, dir.clone()),
                    None => (scene::load(scene)?, dir.clone()),
                };
                let report =
                    modes::report_with_progress(&s.structure, n_modes, cli.quiet || cli.json)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", scene.display()))?;
                let figures = modes::plot(&report, &dir)?;
                if !cli.json {
                    if angles.len() > 1 && !cli.quiet {
                        say!("reference angle {}°:", a.unwrap_or(0.0));
                    }
                    if !cli.quiet {
                        modes::print_table(&mut std::io::stdout().lock(), &report)?;
                        for f in figures {
                            say!("plot: {}", f.display());
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
                say!("{}", serde_json::to_string_pretty(&v)?);
            }
        }
        Some(Command::Check { scene }) => {
            let checked = scene::check(scene)?;
            let s = &checked.scene;
            let st = &s.structure;
            let est = modes::estimate(st);
            let fits = est.bytes <= modes::MAX_DENSE_BYTES;
            let modes_plan = modes::plan(st);
            let (modes_route, modes_bytes, modes_seconds) = match est.route() {
                modes::Route::Dense => ("dense", est.bytes, est.seconds),
                modes::Route::Sparse => ("sparse", est.sparse_bytes, est.sparse_seconds),
            };
            if cli.json {
                let v = serde_json::json!({
                    "modal_basis_bytes": est.bytes,
                    "modal_basis_seconds": est.seconds,
                    "modal_basis_fits": fits,
                    "modes_route": modes_route,
                    "modes_bytes": modes_bytes,
                    "modes_fits": modes_plan.is_ok(),
                    "scene": scene,
                    "ok": true,
                    "beams": st.beams().len(),
                    "joints": st.joints().len(),
                    "unknowns": st.dim(),
                    "steps": s.steps,
                    "controlled": s.control.is_some(),
                    "control_inputs": s.control.as_ref().map_or(0, |c| c.scenario.inputs.len()),
                });
                say!("{}", serde_json::to_string_pretty(&v)?);
            } else if !cli.quiet {
                say!(
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
                say!(
                    "modes: {modes_route} route, about {}, {} on one core{}",
                    modes::human_bytes(modes_bytes),
                    modes::human_seconds(modes_seconds),
                    if modes_plan.is_ok() {
                        ""
                    } else {
                        " — over the cap: modes will refuse this mesh"
                    }
                );
                say!(
                    "modal basis (mpc, sweep, ocp): about {}, {} on one core{}",
                    modes::human_bytes(est.bytes),
                    modes::human_seconds(est.seconds),
                    if fits {
                        String::new()
                    } else {
                        format!(
                            " — over the cap of {}: those commands will refuse this mesh",
                            modes::human_bytes(modes::MAX_DENSE_BYTES)
                        )
                    }
                );
            }
        }
        Some(Command::Mpc { scene, controller, model, plant, omega0, duration, repeat }) => {
            let s = scene::load(scene)?;
            let ov = Overrides {
                controller: kind_of(controller.as_deref())?,
                plant: plant_of(plant.as_deref())?,
                omega0: *omega0,
                duration: *duration,
                model: model_of(model.as_deref())?,
            };
            let out = mpc_out(cli, scene, &control::control_of(&s, &ov)?);
            check_modal_size(&s)?;
            let o =
                control::run_mpc_repeated(&s, &ov, &out, output_options(cli), *repeat as usize)?;
            write_vtk(cli, &s, &o)?;
            print_mpc(&o, cli)?;
        }
        Some(Command::Ocp { scene, controller, model, omega0, export, converge }) => {
            let s = scene::load(scene)?;
            let ov = Overrides {
                controller: kind_of(controller.as_deref())?,
                model: model_of(model.as_deref())?,
                omega0: *omega0,
                ..Default::default()
            };
            check_modal_size(&s)?;
            let mut v = control::first_sample(&s, &ov, export.as_deref(), *converge)?;
            if cli.no_timings {
                if let Some(m) = v.as_object_mut() {
                    m.remove("solve_time_s");
                }
            }
            if cli.json {
                say!("{}", serde_json::to_string_pretty(&v)?);
            } else if !cli.quiet {
                say!(
                    "{} first sample, ω0 = {} ({}): cost {:.6e}, KKT {}, {} iteration{}, {}, status {} ({})",
                    v["controller"].as_str().unwrap_or("?").to_uppercase(),
                    v["omega0"],
                    v["mode"].as_str().unwrap_or("?"),
                    v["cost"].as_f64().unwrap_or(f64::NAN),
                    v["kkt"].as_f64().map_or_else(
                        || "not evaluated after the step".to_string(),
                        |k| format!("{k:.1e}")
                    ),
                    v["iterations"],
                    if v["iterations"].as_u64() == Some(1) { "" } else { "s" },
                    v["solve_time_s"]
                        .as_f64()
                        .map_or_else(|| "time not shown".to_string(), |t| format!("{t:.3} s")),
                    v["status"].as_str().unwrap_or("?"),
                    v["strategy"].as_str().unwrap_or("?")
                );
                if let Some(c) = v["controls"].as_array() {
                    say!("u over the horizon ({} intervals, inputs {}):", c.len(), v["inputs"]);
                    for (k, u) in c.iter().enumerate() {
                        say!("{k:>4} {u}");
                    }
                }
                if let Some(d) = export {
                    say!("exported the problem to {}", d.display());
                }
            }
        }
        Some(Command::Sweep { scene, omega0, controller, model, plant, duration }) => {
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
                    .map(|k| {
                        scene::controller_kind(k.trim()).ok_or_else(|| {
                            anyhow::anyhow!("--controller `{}` (allowed: nmpc, lmpc)", k.trim())
                        })
                    })
                    .collect::<Result<Vec<_>>>()?,
                None => c.sweep_controllers.clone(),
            };
            let models: Vec<mpc::ModelKind> = match model {
                Some(list) => list
                    .split(',')
                    .map(|m| model_of(Some(m.trim())).map(|m| m.unwrap_or(c.controller.model)))
                    .collect::<Result<Vec<_>>>()?,
                None => vec![c.controller.model],
            };
            let ov = Overrides {
                controller: None,
                plant: plant_of(plant.as_deref())?,
                omega0: None,
                duration: *duration,
                // one model: as `--model` of `flexmpc mpc`; several: each run's own
                model: if models.len() == 1 && model.is_some() { Some(models[0]) } else { None },
            };
            let plant = ov.plant.unwrap_or(c.plant);
            let out = sweep_out(cli, scene, &kinds, &models, plant, &omegas);
            check_modal_size(&s)?;
            let o = control::run_sweep_models(
                &s,
                &ov,
                &models,
                &omegas,
                &kinds,
                &out,
                output_options(cli),
            )?;
            if cli.json {
                let v: Vec<serde_json::Value> = o
                    .runs
                    .iter()
                    .map(|r| match &r.result {
                        Ok(res) => control::summary_json(res),
                        Err(e) => serde_json::json!({
                            "omega0": r.omega0, "controller": r.controller.name(), "model": r.model.name(),
                            "stabilised": false, "error": e,
                        }),
                    })
                    .collect();
                say!("{}", serde_json::to_string_pretty(&v)?);
            } else if !cli.quiet {
                say!(
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
                            say!(
                                "{:>5} {:>6} {:>11.3e} {:>9.1} {:>12.2} {:>11.2e} {:>8} {:>8}  {}{}",
                                r.label(),
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
                            say!("{:>5} {:>6} failed: {e}", r.label(), r.omega0)
                        }
                    }
                }
                say!(
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
                    say!("timings not written (--no-timings)");
                } else {
                    let t: Vec<String> =
                        o.timings.iter().map(|p| p.display().to_string()).collect();
                    say!("measured timings: {}", t.join(", "));
                }
                say!("report: {}", o.report.display());
            }
        }
        Some(Command::InternalErrorCheck) => flexmpc::bug_report::fail_on_purpose(),
        None => {
            let path = Path::new(DEFAULT_SCENE_PATH);
            let s = scene::load_str(path, DEFAULT_SCENE)?;
            let out = mpc_out(cli, path, &control::control_of(&s, &Overrides::default())?);
            if chatty(cli) {
                say!(
                    "flexmpc {}: running the default scene {} ({}) — the paper's 2D NMPC example",
                    env!("CARGO_PKG_VERSION"),
                    path.display(),
                    s.description.trim()
                );
            }
            let o = control::run_mpc(&s, &Overrides::default(), &out, output_options(cli))?;
            write_vtk(cli, &s, &o)?;
            print_mpc(&o, cli)?;
            if chatty(cli) {
                say!(
                    "open {} in a browser; `flexmpc --help` lists the commands (mpc, sweep, ocp, \
                     simulate, modes, check)",
                    o.report.display()
                );
            }
        }
    }
    Ok(())
}
