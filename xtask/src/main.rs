//! Project automation for flexmpc: `cargo xtask verify` (and later `bench`).
//!
//! `cargo xtask` is an alias (`.cargo/config.toml`) for `cargo run --release -p xtask --`, so
//! every verification case runs optimised.

mod bench;
mod fuzz;
mod stress;

use anyhow::{bail, Result};
use flexmpc_verification::{all_cases, run_case, Row, Tier};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;

const USAGE: &str = "\
usage: cargo xtask verify [FILTER] [--quick | --full] [--json]

  FILTER   run only the cases whose name contains FILTER (e.g. intrinsic-beam/)
  --quick  only the quick tier (seconds per case; what CI runs)
  --full   every case (the default)
  --json   print the report as a JSON array of {case, metric, value, tolerance, pass}
  --write-docs  also write the report to docs/verification.md (command, date, machine, run time)

Reports are also written to target/verify/report.md and target/verify/report.json.
The exit code is non-zero if any case fails.

Also: cargo xtask stress [FILTER] [--quick], cargo xtask fuzz [--cases N] [--seed S] [--show I]
(docs/stress.md); each takes --help.";

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("verify") => verify(&args[1..]),
        Some("bench") => bench::main(&args[1..]),
        Some("stress") => stress::main(&args[1..]),
        Some("fuzz") => fuzz::main(&args[1..]),
        Some("-h") | Some("--help") | Some("help") | None => {
            println!("{USAGE}");
            Ok(())
        }
        Some(other) => bail!("unknown xtask command `{other}`\n{USAGE}"),
    }
}

fn verify(args: &[String]) -> Result<()> {
    let mut filter: Option<&str> = None;
    let mut quick = false;
    let mut json = false;
    let mut write_docs = false;
    let started = std::time::Instant::now();
    for arg in args {
        match arg.as_str() {
            "--quick" => quick = true,
            "--full" => quick = false,
            "--json" => json = true,
            "--write-docs" => write_docs = true,
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(());
            }
            s if s.starts_with("--") => bail!("unknown option `{s}`\n{USAGE}"),
            s => {
                if filter.replace(s).is_some() {
                    bail!("only one FILTER may be given\n{USAGE}");
                }
            }
        }
    }
    let cases: Vec<_> = all_cases()
        .into_iter()
        .filter(|c| filter.is_none_or(|f| c.name.contains(f)))
        .filter(|c| !quick || c.tier == Tier::Quick)
        .collect();
    if cases.is_empty() && filter.is_none() {
        println!("no verification case registered yet (quick tier only: {quick})");
        return Ok(());
    }
    if cases.is_empty() {
        bail!(
            "no verification case matches filter {:?} (quick tier only: {quick})",
            filter.unwrap_or("")
        );
    }
    let mut rows: Vec<Row> = Vec::new();
    let progress = !json && std::io::stderr().is_terminal();
    for case in &cases {
        if progress {
            eprint!("running {:<50}\r", case.name);
            let _ = std::io::stderr().flush();
        }
        rows.extend(run_case(case));
    }
    let table = markdown_table(&rows);
    let report = json_report(&rows);
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/verify");
    std::fs::create_dir_all(&dir)?;
    std::fs::write(dir.join("report.md"), &table)?;
    std::fs::write(dir.join("report.json"), serde_json::to_string_pretty(&report)?)?;
    if write_docs {
        write_verification_docs(args, &table, &rows, started.elapsed().as_secs_f64())?;
    }
    let failed = rows.iter().filter(|r| !r.metric.pass()).count();
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        if progress {
            eprint!("{:<70}\r", "");
        }
        println!("{table}");
        println!("{} passed, {} failed", rows.len() - failed, failed);
    }
    if failed > 0 {
        bail!("{failed} verification metric(s) failed");
    }
    Ok(())
}

fn markdown_table(rows: &[Row]) -> String {
    let mut out = String::from(
        "| case | metric | value | tolerance | result | time (s) |\n|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let m = &r.metric;
        let op = match m.comparison {
            flexmpc_verification::Comparison::AtMost => "≤",
            flexmpc_verification::Comparison::AtLeast => "≥",
        };
        out.push_str(&format!(
            "| {} | {} | {:.3e} | {} {:.1e} | {} | {:.2} |\n",
            r.case,
            m.metric,
            m.value,
            op,
            m.tolerance,
            if m.pass() { "PASS" } else { "FAIL" },
            r.seconds
        ));
    }
    out
}

fn json_report(rows: &[Row]) -> serde_json::Value {
    let finite =
        |x: f64| if x.is_finite() { serde_json::json!(x) } else { serde_json::Value::Null };
    serde_json::Value::Array(
        rows.iter()
            .map(|r| {
                serde_json::json!({
                    "case": r.case,
                    "metric": r.metric.metric,
                    "value": finite(r.metric.value),
                    "tolerance": finite(r.metric.tolerance),
                    "pass": r.metric.pass(),
                })
            })
            .collect(),
    )
}

/// `--write-docs`: docs/verification.md = a header (command, date, machine, run time) and the
/// report table of this run.
fn write_verification_docs(args: &[String], table: &str, rows: &[Row], seconds: f64) -> Result<()> {
    let date = std::process::Command::new("date")
        .args(["-u", "+%Y-%m-%d %H:%M UTC"])
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|d| d.trim().to_string())
        .unwrap_or_else(|| "(date unavailable)".into());
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|c| {
            c.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let failed = rows.iter().filter(|r| !r.metric.pass()).count();
    // The same table as target/verify/report.md, with `|` inside metric names escaped so that
    // the page renders.
    let table: String = table
        .lines()
        .take(2)
        .map(|l| format!("{l}\n"))
        .chain(rows.iter().map(|r| {
            let m = &r.metric;
            let op = match m.comparison {
                flexmpc_verification::Comparison::AtMost => "≤",
                flexmpc_verification::Comparison::AtLeast => "≥",
            };
            format!(
                "| {} | {} | {:.3e} | {} {:.1e} | {} | {:.2} |\n",
                r.case.replace('|', "\\|"),
                m.metric.replace('|', "\\|"),
                m.value,
                op,
                m.tolerance,
                if m.pass() { "PASS" } else { "FAIL" },
                r.seconds
            )
        }))
        .collect();
    let text = format!(
        "# Verification\n\n\
         Generated by `cargo xtask verify {}` on {date}, on {cpu} ({threads} hardware threads, \
         {} {}); run time {seconds:.0} s wall (other jobs may have shared the machine). \
         Do not edit: rerun the command to update it.\n\n\
         {} metrics: {} passed, {failed} failed.\n\n\
         Each row is one metric of a verification case `<crate>/<case>` (registered in \
         `tests/src/`, one module per crate): the measured value, the tolerance it is compared \
         with (`≤` for errors, drifts and residuals, `≥` for convergence orders and margins), \
         the result, and the case's wall time. `cargo xtask verify` runs every case, \
         `--quick` the CI tier; `cargo xtask verify intrinsic-beam/` filters by name. \
         The same table is written to `target/verify/report.md` and as JSON to \
         `target/verify/report.json`.\n\n{table}",
        args.join(" "),
        std::env::consts::OS,
        std::env::consts::ARCH,
        rows.len(),
        rows.len() - failed,
    );
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/verification.md");
    std::fs::write(&path, text)?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
