//! `cargo xtask stress [--quick] [FILTER]`: the numerical stress experiments (long
//! runs, large disturbances, extreme stiffness ratios, near-singular joint angles, random
//! structures), each sub-run inside `catch_unwind` with every output checked for finiteness.
//! Prints a table and writes `target/stress/report.md` and `report.json`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use flexmpc_verification::stress::{experiments, Size, Status, SubRun};
use flexmpc_verification::Comparison;

const USAGE: &str = "\
usage: cargo xtask stress [FILTER] [--quick]

  FILTER   run only the experiments whose name contains FILTER (e.g. singular/)
  --quick  the small subset at CI sizes (well under a minute)

Each sub-run ends `ok` (finite results), `error` (a typed error of the library: acceptable
where the table says so), `NON-FINITE` or `PANIC` (defects). Reports: target/stress/report.md
and target/stress/report.json. The exit code is non-zero if any sub-run fails.";

/// Entry point of the `stress` subcommand.
pub fn main(args: &[String]) -> Result<()> {
    let mut quick = false;
    let mut filter: Option<&str> = None;
    for a in args {
        match a.as_str() {
            "--quick" => quick = true,
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
    let size = if quick { Size::Quick } else { Size::Full };
    let chosen: Vec<_> = experiments()
        .into_iter()
        .filter(|e| !quick || e.in_quick)
        .filter(|e| filter.is_none_or(|f| e.name.contains(f)))
        .collect();
    if chosen.is_empty() {
        bail!("no stress experiment matches {:?}", filter.unwrap_or(""));
    }
    // Panics are caught and reported in the table; keep the default hook from printing them.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|info| {
        eprintln!("(caught) panic {}", info.location().map(|l| l.to_string()).unwrap_or_default());
    }));
    let start = Instant::now();
    let mut rows: Vec<(&'static str, SubRun)> = Vec::new();
    for e in &chosen {
        eprintln!("stress: {} …", e.name);
        for r in (e.run)(size) {
            eprintln!("  {:<10} {:>8.2} s  {}", r.status.label(), r.seconds, r.label);
            rows.push((e.name, r));
        }
    }
    std::panic::set_hook(hook);
    let total = start.elapsed().as_secs_f64();
    let table = markdown(&rows, size, total);
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/stress");
    std::fs::create_dir_all(&dir)?;
    std::fs::write(dir.join("report.md"), &table)?;
    std::fs::write(
        dir.join("report.json"),
        serde_json::to_string_pretty(&json(&rows, size, total))?,
    )?;
    println!("{table}");
    let failed = rows.iter().filter(|r| !r.1.pass()).count();
    println!(
        "{} sub-runs: {} passed, {} failed; wall time {total:.1} s; reports in {}",
        rows.len(),
        rows.len() - failed,
        failed,
        dir.display()
    );
    if failed > 0 {
        bail!("{failed} stress sub-run(s) failed");
    }
    Ok(())
}

fn status_text(r: &SubRun) -> String {
    let verdict = if r.pass() { "PASS" } else { "FAIL" };
    match &r.status {
        Status::Ok => format!("ok ({verdict})"),
        Status::Error(e) => format!("error ({verdict}): {e}"),
        Status::NonFinite(e) => format!("NON-FINITE (FAIL): {e}"),
        Status::Panic(e) => format!("PANIC (FAIL): {e}"),
    }
}

fn figure_text(r: &SubRun) -> String {
    let mut parts: Vec<String> = r
        .metrics
        .iter()
        .map(|m| {
            let bound = if m.tolerance.is_finite() {
                let op = match m.comparison {
                    Comparison::AtMost => "≤",
                    Comparison::AtLeast => "≥",
                };
                format!(" ({op} {:.1e}{})", m.tolerance, if m.pass() { "" } else { " FAIL" })
            } else {
                String::new()
            };
            format!("{} {}{bound}", m.metric, fmt(m.value))
        })
        .collect();
    if !r.note.is_empty() {
        parts.push(r.note.clone());
    }
    parts.join("; ").replace('|', "/")
}

fn fmt(v: f64) -> String {
    if v == v.trunc() && v.abs() < 1e6 {
        format!("{v:.0}")
    } else if (1e-2..1e4).contains(&v.abs()) {
        format!("{v:.3}")
    } else {
        format!("{v:.2e}")
    }
}

fn markdown(rows: &[(&str, SubRun)], size: Size, total: f64) -> String {
    let mut out = format!(
        "Stress run ({size:?} sizes), {} sub-runs, wall time {total:.1} s\n\n\
         | experiment | case | result | figures | time (s) |\n|---|---|---|---|---|\n",
        rows.len()
    );
    for (name, r) in rows {
        out.push_str(&format!(
            "| {name} | {} | {} | {} | {:.2} |\n",
            r.label.replace('|', "/"),
            status_text(r).replace('|', "/"),
            figure_text(r),
            r.seconds
        ));
    }
    out
}

fn json(rows: &[(&str, SubRun)], size: Size, total: f64) -> serde_json::Value {
    let finite =
        |x: f64| if x.is_finite() { serde_json::json!(x) } else { serde_json::Value::Null };
    serde_json::json!({
        "size": format!("{size:?}"),
        "wall_time_s": total,
        "runs": rows.iter().map(|(name, r)| serde_json::json!({
            "experiment": name,
            "case": r.label,
            "status": r.status.label(),
            "message": match &r.status {
                Status::Ok => String::new(),
                Status::Error(e) | Status::NonFinite(e) | Status::Panic(e) => e.clone(),
            },
            "pass": r.pass(),
            "note": r.note,
            "seconds": r.seconds,
            "metrics": r.metrics.iter().map(|m| serde_json::json!({
                "metric": m.metric,
                "value": finite(m.value),
                "tolerance": finite(m.tolerance),
                "pass": m.pass(),
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    })
}
