//! `flexmpc`: the command-line front end — scene files, simulations, CSV outputs and plots.
//!
//! `flexmpc simulate <scene.toml>` runs a scene's constrained FE plant (multibody-constraints)
//! and writes `timeseries.csv` (energy, joint angles, end positions, support reactions,
//! inputs); `flexmpc check <scene.toml>` only validates it. Without arguments it runs the
//! built-in default scene (`scenes/cantilever.toml`) and says where its results are.

use flexmpc::{modes, run, scene};

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::{Parser, Subcommand};

use flexmpc::DEFAULT_SCENE;

#[derive(Parser)]
#[command(
    name = "flexmpc",
    version,
    about = "Simulation and control of very flexible multibody structures"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// No progress bar.
    #[arg(long, global = true)]
    quiet: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene and write its time series (CSV) to an output folder.
    Simulate {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Output folder (default `out/<scene name>`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Constrained linear modes of a scene's structure: frequencies, labels, plots.
    Modes {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Reference angle (degrees) of the structure's first joint (default: the scene's).
        #[arg(long, allow_hyphen_values = true)]
        angle: Option<f64>,
        /// Number of modes, rigid ones included.
        #[arg(long, default_value_t = 8)]
        modes: usize,
        /// Print `{"frequencies_rad_s": [..], "labels": [..], "n_rigid": n}` instead of a table.
        #[arg(long)]
        json: bool,
        /// Output folder for the plots (default `out/<scene name>/modes`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Validate a scene file without running it.
    Check {
        /// Scene file (TOML).
        scene: PathBuf,
    },
}

fn default_out(scene: &Path) -> PathBuf {
    let stem = scene
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "scene".into());
    PathBuf::from("out").join(stem)
}

fn report(summary: &run::RunSummary, quiet: bool) {
    if quiet {
        return;
    }
    println!(
        "{} steps in {:.2} s; energy + potential {:.6e} → {:.6e}; max velocity-constraint violation {:.1e}; wrote {}",
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

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Simulate { scene, out }) => {
            let s = scene::load(&scene)?;
            let out = out.unwrap_or_else(|| default_out(&scene));
            let summary = run::simulate(s, &out, cli.quiet)?;
            report(&summary, cli.quiet);
        }
        Some(Command::Modes { scene, angle, modes: n_modes, json, out }) => {
            if n_modes == 0 {
                anyhow::bail!("--modes must be at least 1, got 0");
            }
            let s = match angle {
                Some(a) => scene::load_at_angle(&scene, a)?,
                None => scene::load(&scene)?,
            };
            let report = modes::report(s.plant.structure(), n_modes)?;
            let dir = out.unwrap_or_else(|| default_out(&scene).join("modes"));
            let figures = modes::plot(&report, &dir)?;
            if json {
                let summary = serde_json::json!({
                    "frequencies_rad_s": report.frequencies_rad_s,
                    "labels": report.labels,
                    "n_rigid": report.n_rigid,
                });
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                modes::print_table(&report);
                if !cli.quiet {
                    for f in figures {
                        println!("plot: {}", f.display());
                    }
                }
            }
        }
        Some(Command::Check { scene }) => {
            let s = scene::load(&scene)?;
            if !cli.quiet {
                let st = s.plant.structure();
                println!(
                    "{}: ok ({} beams, {} joints/supports, {} unknowns, {} steps)",
                    scene.display(),
                    st.beams().len(),
                    st.joints().len(),
                    st.dim(),
                    s.steps
                );
            }
        }
        None => {
            let path = Path::new("scenes/cantilever.toml");
            let s = scene::load_str(path, DEFAULT_SCENE)?;
            let out = default_out(path);
            if !cli.quiet {
                println!(
                    "flexmpc {}: running the default scene {} ({})",
                    env!("CARGO_PKG_VERSION"),
                    path.display(),
                    s.description.trim()
                );
            }
            let summary = run::simulate(s, &out, cli.quiet)?;
            report(&summary, cli.quiet);
            if !cli.quiet {
                println!(
                    "results are in {}/ (run `flexmpc simulate <scene.toml>` for other scenes)",
                    out.display()
                );
            }
        }
    }
    Ok(())
}
