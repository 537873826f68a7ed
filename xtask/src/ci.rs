//! `cargo xtask ci`: the CI job, one step after another, each step's wall time printed.
//!
//! Steps: the repository checks of [`crate::tidy`] (seconds, so a broken reference fails
//! before anything compiles), `cargo fmt --all --check`, `cargo clippy` on every target with
//! `-D warnings`, `cargo doc --workspace --no-deps` with `RUSTDOCFLAGS=-D warnings`,
//! `cargo test --workspace --release` (output streamed, so the test runner's closing lines
//! appear), and the quick verification tier (`cargo xtask verify --quick`). The first failing
//! step ends the job with a non-zero exit code.
//!
//! Clippy runs in the release profile (`--release`): its build scripts and proc macros are
//! then the same units the release test build uses, instead of a second set built with the
//! dev profile's `opt-level = 3` for dependencies (docs/ci.md has the timings).

use anyhow::{bail, Result};
use std::path::Path;
use std::process::Command;
use std::time::Instant;

const USAGE: &str = "\
usage: cargo xtask ci

Runs, in order, stopping at the first failure: tidy (xtask/src/tidy.rs), cargo fmt --all
--check, cargo clippy --workspace --all-targets --release -- -D warnings, cargo doc
--workspace --no-deps --release (RUSTDOCFLAGS=-D warnings), cargo test --workspace --release, cargo
xtask verify --quick. Prints each step's wall time and a summary.";

/// One CI step: a name and what runs.
enum Step {
    /// A command line run in the workspace root, with extra environment variables.
    Cargo(&'static [&'static str], &'static [(&'static str, &'static str)]),
    /// The repository checks, in process.
    Tidy,
    /// The quick verification tier, in process.
    VerifyQuick,
}

const STEPS: &[(&str, Step)] = &[
    ("tidy", Step::Tidy),
    ("fmt", Step::Cargo(&["fmt", "--all", "--check"], &[])),
    (
        "clippy",
        Step::Cargo(
            &["clippy", "--workspace", "--all-targets", "--release", "--", "-D", "warnings"],
            &[],
        ),
    ),
    (
        "doc",
        Step::Cargo(
            &["doc", "--workspace", "--no-deps", "--release"],
            &[("RUSTDOCFLAGS", "-D warnings")],
        ),
    ),
    ("test", Step::Cargo(&["test", "--workspace", "--release"], &[])),
    ("verify --quick", Step::VerifyQuick),
];

/// Runs the CI job (see the module docs).
pub fn main(args: &[String]) -> Result<()> {
    if let Some(a) = args.first() {
        if a == "-h" || a == "--help" {
            println!("{USAGE}");
            return Ok(());
        }
        bail!("unknown argument `{a}`\n{USAGE}");
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask sits in the workspace");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    let started = Instant::now();
    let mut times: Vec<(&str, f64)> = Vec::new();
    let mut failed: Option<String> = None;
    for (name, step) in STEPS {
        eprintln!("==> ci: {name}");
        let t = Instant::now();
        let result: Result<()> = match step {
            Step::Tidy => {
                let problems = crate::tidy::check_all(root);
                for p in &problems {
                    eprintln!("{p}");
                }
                if problems.is_empty() {
                    Ok(())
                } else {
                    Err(anyhow::anyhow!("{} tidy problem(s)", problems.len()))
                }
            }
            Step::Cargo(argv, envs) => {
                let mut cmd = Command::new(&cargo);
                cmd.args(*argv).current_dir(root);
                for (k, v) in *envs {
                    cmd.env(k, v);
                }
                let status = cmd.status()?;
                if status.success() {
                    Ok(())
                } else {
                    Err(anyhow::anyhow!("`cargo {}` exited with {status}", argv.join(" ")))
                }
            }
            Step::VerifyQuick => crate::verify(&["--quick".to_string()]),
        };
        let seconds = t.elapsed().as_secs_f64();
        times.push((name, seconds));
        eprintln!(
            "==> ci: {name} {} in {seconds:.1} s",
            if result.is_ok() { "ok" } else { "FAILED" }
        );
        if let Err(e) = result {
            failed = Some(format!("{name}: {e}"));
            break;
        }
    }
    eprintln!("==> ci: wall time per step");
    for (name, seconds) in &times {
        eprintln!("    {name:<16} {seconds:>8.1} s");
    }
    eprintln!("    {:<16} {:>8.1} s", "total", started.elapsed().as_secs_f64());
    match failed {
        Some(f) => bail!("ci failed at {f}"),
        None => {
            eprintln!("==> ci: all steps passed");
            Ok(())
        }
    }
}
