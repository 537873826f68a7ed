//! `cargo xtask bench`: run time against error for the four studies — (a) FE mesh
//! against frequency error, (b) ROM mode count against trajectory error, (c) time step against
//! error per integrator, (d) closed-loop cost against solve time per controller — written as
//! markdown, CSV, JSON and SVG plots to `target/bench/` (`--publish`: also to `docs/perf/`);
//! and (e) `modes-scaling`, the time and memory of the modal basis against the mesh.
//!
//! Every timing is the median of repeated runs (`Instant`) on one thread (the rayon pool is
//! built with one thread); each table header records the command, the machine, the load
//! average at the start and end of its study and the process CPU time over wall time.

mod control;
mod mesh;
mod modes;
mod plot;
mod report;
mod timestep;

pub(crate) use flexmpc_verification::perf::{orders, timed};

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use report::Study;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub(crate) const USAGE: &str = "\
usage: cargo xtask bench [--quick] [--publish] [WHICH ...]

  WHICH      any of: mesh (a), modes (b), timestep (c), control (d), modes-scaling (e: time
             and memory of the modal basis against the mesh); default: all five
  --quick    a coarse subset (under 1 minute on 2 loaded cores); the full run takes about 5
             minutes there
  --publish  also copy the tables (markdown) and plots (SVG) to docs/perf/

Writes target/bench/<study>.{md,csv,json,svg} and target/bench/summary.md.
Timings: median of repeated runs, one thread. Prefer a quiet machine: the header of each
table records the load average and the CPU/wall ratio of the run.";

/// The studies, in report order: (short name, letter, runner).
type Runner = fn(&mut Ctx) -> Result<Study>;
const STUDIES: [(&str, &str, Runner); 5] = [
    ("mesh", "a", mesh::run),
    ("modes", "b", modes::run),
    ("timestep", "c", timestep::run),
    ("control", "d", control::run),
    ("modes-scaling", "e", modes::run_scaling),
];

/// What every study needs: the tier, the command line, the machine and progress reporting.
pub(crate) struct Ctx {
    /// Coarse subset (`--quick`).
    pub quick: bool,
    /// The exact command, for table headers.
    pub command: String,
    /// Static machine description (CPU model, cores).
    pub machine: String,
    bar: Option<ProgressBar>,
    started: Instant,
}

impl Ctx {
    /// Reports progress: a bar message on a terminal, a plain line otherwise.
    pub fn progress(&self, what: &str) {
        match &self.bar {
            Some(b) => b.set_message(what.to_string()),
            None => eprintln!("[bench {:>6.1} s] {what}", self.started.elapsed().as_secs_f64()),
        }
    }

    /// Advances the bar by one unit of work (no-op without a terminal).
    pub fn tick(&self) {
        if let Some(b) = &self.bar {
            b.inc(1);
        }
    }

    /// Sets the number of work units of the running study (each followed by [`Self::tick`]).
    pub fn plan(&self, units: u64) {
        if let Some(b) = &self.bar {
            b.set_length(units);
        }
    }

    /// Resets the bar for the next study.
    fn start_study(&self, name: &str) {
        match &self.bar {
            Some(b) => {
                b.reset();
                b.set_prefix(name.to_string());
            }
            None => {
                eprintln!("[bench {:>6.1} s] study {name}", self.started.elapsed().as_secs_f64())
            }
        }
    }
}

/// The 1-, 5- and 15-minute load averages.
pub(crate) fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|| "unknown".into())
}

fn machine() -> String {
    let cpus = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0);
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    format!("{cpus} CPUs (nproc), {model}")
}

/// A verification-crate study result as an `anyhow` result.
pub(crate) fn ok<T>(r: flexmpc_verification::perf::Result<T>) -> Result<T> {
    r.map_err(anyhow::Error::from_boxed)
}

/// Entry point of `cargo xtask bench ARGS`.
pub fn main(args: &[String]) -> Result<()> {
    let mut quick = false;
    let mut publish = false;
    let mut which: Vec<&str> = Vec::new();
    for arg in args {
        match arg.as_str() {
            "--quick" => quick = true,
            "--full" => quick = false,
            "--publish" => publish = true,
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(());
            }
            s if s.starts_with("--") => bail!("unknown option `{s}`\n{USAGE}"),
            s => match STUDIES.iter().find(|(n, l, _)| s == *n || s == *l) {
                Some((n, _, _)) => which.push(n),
                None => bail!(
                    "unknown study `{s}` (mesh, modes, timestep, control, modes-scaling)\n{USAGE}"
                ),
            },
        }
    }
    if which.is_empty() {
        which = STUDIES.iter().map(|(n, _, _)| *n).collect();
    }
    // one worker thread: every timing is single-core (mpc sweeps and parallel intervals use
    // rayon; nothing else spawns threads)
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .context("building the one-thread rayon pool")?;
    let mut command = String::from("cargo xtask bench");
    for a in args {
        command.push(' ');
        command.push_str(a);
    }
    let bar = std::io::stderr().is_terminal().then(|| {
        let b = ProgressBar::new(1);
        b.set_style(
            ProgressStyle::with_template(
                "{prefix:>9} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b
    });
    let mut ctx = Ctx { quick, command, machine: machine(), bar, started: Instant::now() };
    let dir = repo_root().join("target/bench");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut studies = Vec::new();
    for (name, _, runner) in STUDIES.iter().filter(|(n, _, _)| which.contains(n)) {
        ctx.start_study(name);
        let load0 = load_average();
        let (cpu0, t0) = (ocp_transcription::process_cpu_time().unwrap_or(0.0), Instant::now());
        let mut study = runner(&mut ctx).with_context(|| format!("study `{name}`"))?;
        let wall = t0.elapsed().as_secs_f64();
        study.header = report::Header {
            command: ctx.command.clone(),
            machine: ctx.machine.clone(),
            load_start: load0,
            load_end: load_average(),
            wall_s: wall,
            cpu_over_wall: (ocp_transcription::process_cpu_time().unwrap_or(0.0) - cpu0)
                / wall.max(1e-9),
            quick,
        };
        study.write(&dir)?;
        ctx.progress(&format!("{name}: done in {wall:.1} s"));
        studies.push(study);
    }
    if let Some(b) = &ctx.bar {
        b.finish_and_clear();
    }
    let summary = report::summary(&studies);
    std::fs::write(dir.join("summary.md"), &summary)?;
    if publish {
        let docs = repo_root().join("docs/perf");
        std::fs::create_dir_all(&docs)?;
        for s in &studies {
            s.publish(&dir, &docs)?;
        }
        std::fs::write(docs.join("summary.md"), &summary)?;
        eprintln!("copied tables and plots to {}", docs.display());
    }
    println!("{summary}");
    eprintln!(
        "wrote {} ({:.0} s in all)",
        dir.join("summary.md").display(),
        ctx.started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The repository root (parent of `xtask/`).
pub(crate) fn repo_root() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().map_or_else(|| manifest.join(".."), Path::to_path_buf)
}
