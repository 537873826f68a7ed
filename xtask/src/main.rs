//! Project automation for flexmpc: `cargo xtask ci`, `verify`, `bench`, `stress`, `fuzz`, `tidy`.
//!
//! `cargo xtask` is an alias (`.cargo/config.toml`) for `cargo run --release -p xtask --`, so
//! every verification case runs optimised.

mod bench;
mod ci;
mod fuzz;
mod peers;
mod stress;
mod tidy;

use anyhow::{bail, Result};
use flexmpc_verification::{all_cases, run_case, Row, Tier};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;

const USAGE: &str = "\
usage: cargo xtask verify [FILTER] [--quick | --full] [--json] [--list] [--write-docs]

  FILTER   run only the cases whose name contains FILTER (e.g. intrinsic-beam/)
  --quick  only the quick tier (seconds per case; what CI runs)
  --full   every case (the default)
  --json   print the report as a JSON array of {case, metric, value, tolerance, pass}
  --list   list the selected cases and their tier without running them
  --write-docs  also write the report to docs/verification.md (command, date, machine, run time)

Progress: one line per case on stderr, `[k/n] case … done in X s (elapsed, failed so far)`
(on a terminal the running case is shown until it finishes).
Reports are written to target/verify/: report.md (command, date, machine, run time, the
table, cases by run time), report.json (the rows) and summary.json (tier, filter, counts,
wall and CPU time, per-case times); they are rewritten after every case, so an interrupted
run leaves the finished cases (summary.json then has complete = false).
The exit code is non-zero if any case fails.

Also: cargo xtask stress [FILTER] [--quick], cargo xtask fuzz [--cases N] [--seed S] [--show I]
(docs/stress.md); each takes --help. cargo xtask ci runs the CI job (fmt, clippy, doc, tests,
the quick tier, each step timed); cargo xtask tidy the repository checks of xtask/src/tidy.rs.";

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // bit-reproducible results whatever the core count: faer's dense kernels run sequentially
    // (the verification cases and sweeps are what run in parallel), as in the `flexmpc` CLI
    faer::set_global_parallelism(faer::Par::Seq);
    match args.first().map(String::as_str) {
        Some("verify") => verify(&args[1..]),
        Some("bench") if args.get(1).map(String::as_str) == Some("peers") => {
            peers::main(&args[2..])
        }
        Some("bench") => bench::main(&args[1..]),
        Some("stress") => stress::main(&args[1..]),
        Some("fuzz") => fuzz::main(&args[1..]),
        Some("ci") => ci::main(&args[1..]),
        Some("tidy") => tidy_main(),
        Some("-h") | Some("--help") | Some("help") | None => {
            println!("{USAGE}");
            Ok(())
        }
        Some(other) => bail!("unknown xtask command `{other}`\n{USAGE}"),
    }
}

/// `cargo xtask tidy`: the repository checks (also `#[test]`s of this crate).
fn tidy_main() -> Result<()> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let problems = tidy::check_all(&root);
    for p in &problems {
        eprintln!("{p}");
    }
    if !problems.is_empty() {
        bail!("{} tidy problem(s)", problems.len());
    }
    println!("tidy: references, crate edges, module cycles and file lengths are clean");
    Ok(())
}

fn verify(args: &[String]) -> Result<()> {
    let mut filter: Option<&str> = None;
    let mut quick = false;
    let mut json = false;
    let mut write_docs = false;
    let mut list = false;
    let started = std::time::Instant::now();
    for arg in args {
        match arg.as_str() {
            "--quick" => quick = true,
            "--full" => quick = false,
            "--json" => json = true,
            "--write-docs" => write_docs = true,
            "--list" => list = true,
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
    if list {
        for c in &cases {
            println!("{:<6} {}", if c.tier == Tier::Quick { "quick" } else { "full" }, c.name);
        }
        let quick_n = cases.iter().filter(|c| c.tier == Tier::Quick).count();
        println!("{} case(s): {quick_n} quick, {} full only", cases.len(), cases.len() - quick_n);
        return Ok(());
    }
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
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/verify");
    std::fs::create_dir_all(&dir)?;
    let run = RunInfo {
        command: format!("cargo xtask verify {}", args.join(" ")).trim_end().to_string(),
        tier: if quick { "quick" } else { "full" },
        filter: filter.map(str::to_string),
        date: date_utc(),
        machine: machine(),
        n_cases: cases.len(),
    };
    let mut rows: Vec<Row> = Vec::new();
    let mut times: Vec<(String, f64, usize, usize)> = Vec::new();
    let terminal = std::io::stderr().is_terminal();
    let n = cases.len();
    eprintln!("{}: {n} case(s), {} tier", run.command, run.tier);
    for (k, case) in cases.iter().enumerate() {
        if terminal {
            eprint!(
                "[{}/{n}] {:<50} running… (elapsed {})\r",
                k + 1,
                case.name,
                hms(started.elapsed().as_secs_f64())
            );
            let _ = std::io::stderr().flush();
        }
        let case_rows = run_case(case);
        let seconds = case_rows.first().map_or(0.0, |r| r.seconds);
        let failed = case_rows.iter().filter(|r| !r.metric.pass()).count();
        times.push((case.name.to_string(), seconds, case_rows.len(), failed));
        rows.extend(case_rows);
        let failed_total = rows.iter().filter(|r| !r.metric.pass()).count();
        eprintln!(
            "[{}/{n}] {:<50} {:>8.2} s, {} metric(s){} (elapsed {}, {failed_total} failed so far)",
            k + 1,
            case.name,
            seconds,
            times.last().map_or(0, |t| t.2),
            if failed > 0 { format!(", {failed} FAILED") } else { String::new() },
            hms(started.elapsed().as_secs_f64())
        );
        write_reports(&dir, &run, &rows, &times, started.elapsed().as_secs_f64(), k + 1 == n)?;
    }
    let table = markdown_table(&rows);
    let report = json_report(&rows);
    if write_docs {
        write_verification_docs(args, &table, &rows, started.elapsed().as_secs_f64())?;
    }
    let failed = rows.iter().filter(|r| !r.metric.pass()).count();
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!("{table}");
        println!(
            "{} passed, {} failed; {} case(s) in {} wall, {:.1} s CPU; reports in {}",
            rows.len() - failed,
            failed,
            n,
            hms(started.elapsed().as_secs_f64()),
            ocp_transcription::process_cpu_time().unwrap_or(f64::NAN),
            dir.display()
        );
    }
    if failed > 0 {
        bail!("{failed} verification metric(s) failed");
    }
    Ok(())
}

/// What a verification run was: written at the top of the reports.
struct RunInfo {
    command: String,
    tier: &'static str,
    filter: Option<String>,
    date: String,
    machine: String,
    n_cases: usize,
}

/// `h:mm:ss`.
fn hms(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    format!("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60)
}

fn date_utc() -> String {
    std::process::Command::new("date")
        .args(["-u", "+%Y-%m-%d %H:%M UTC"])
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|d| d.trim().to_string())
        .unwrap_or_else(|| "(date unavailable)".into())
}

/// CPU model, hardware threads, OS and architecture.
fn machine() -> String {
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
    format!(
        "{cpu} ({threads} hardware threads, {} {})",
        std::env::consts::OS,
        std::env::consts::ARCH
    )
}

/// Writes `report.md`, `report.json` and `summary.json` of the rows so far into `dir`.
fn write_reports(
    dir: &std::path::Path,
    run: &RunInfo,
    rows: &[Row],
    times: &[(String, f64, usize, usize)],
    wall: f64,
    complete: bool,
) -> Result<()> {
    let failed = rows.iter().filter(|r| !r.metric.pass()).count();
    let cpu = ocp_transcription::process_cpu_time();
    let load = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "?".into());
    let mut md = format!(
        "# Verification report\n\n`{}` ({} tier{}), started {}, on {}.\n\n\
         {}{} of {} case(s), {} metric(s): {} passed, {failed} failed. Run time {} wall \
         ({wall:.0} s), {} CPU (user + system); load average at the last case {load}.\n\n",
        run.command,
        run.tier,
        run.filter.as_ref().map(|f| format!(", filter `{f}`")).unwrap_or_default(),
        run.date,
        run.machine,
        if complete { "" } else { "INCOMPLETE (still running or interrupted): " },
        times.len(),
        run.n_cases,
        rows.len(),
        rows.len() - failed,
        hms(wall),
        cpu.map_or_else(|| "?".to_string(), |c| format!("{c:.0} s")),
    );
    md.push_str(&markdown_table(rows));
    md.push_str(
        "\n## Cases by run time\n\n| case | time (s) | metrics | failed |\n|---|---|---|---|\n",
    );
    let mut sorted: Vec<&(String, f64, usize, usize)> = times.iter().collect();
    sorted.sort_by(|a, b| b.1.total_cmp(&a.1));
    for (name, secs, m, f) in sorted {
        md.push_str(&format!("| {name} | {secs:.2} | {m} | {f} |\n"));
    }
    std::fs::write(dir.join("report.md"), md)?;
    std::fs::write(dir.join("report.json"), serde_json::to_string_pretty(&json_report(rows))?)?;
    let summary = serde_json::json!({
        "command": run.command,
        "tier": run.tier,
        "filter": run.filter,
        "started": run.date,
        "machine": run.machine,
        "complete": complete,
        "cases_total": run.n_cases,
        "cases_done": times.len(),
        "metrics": rows.len(),
        "passed": rows.len() - failed,
        "failed": failed,
        "wall_time_s": wall,
        "cpu_time_s": cpu,
        "load_average_1min": load.parse::<f64>().ok(),
        "cases": times
            .iter()
            .map(|(name, secs, m, f)| serde_json::json!({
                "case": name, "seconds": secs, "metrics": m, "failed": f
            }))
            .collect::<Vec<_>>(),
    });
    std::fs::write(dir.join("summary.json"), serde_json::to_string_pretty(&summary)?)?;
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
            r.case.replace('|', "\\|"),
            m.metric.replace('|', "\\|"),
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
    let date = date_utc();
    let machine = machine();
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
         Generated by `cargo xtask verify {}` on {date}, on {machine}; run time {seconds:.0} s \
         wall (other jobs may have shared the machine). \
         Do not edit the table: rerun the command to update it (the sections after the table \
         are written by hand and kept).\n\n\
         {} metrics: {} passed, {failed} failed.\n\n\
         Each row is one metric of a verification case `<crate>/<case>` (registered in \
         `tests/src/`, one module per crate): the measured value, the tolerance it is compared \
         with (`≤` for errors, drifts and residuals, `≥` for convergence orders and margins), \
         the result, and the case's wall time. `cargo xtask verify` runs every case, \
         `--quick` the CI tier; `cargo xtask verify intrinsic-beam/` filters by name. \
         The same table is written to `target/verify/report.md` and as JSON to \
         `target/verify/report.json`.\n\n{table}",
        args.join(" "),
        rows.len(),
        rows.len() - failed,
    );
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/verification.md");
    // the hand-written log after the generated table (from its first `## ` heading) is kept
    let log = std::fs::read_to_string(&path).ok().and_then(|old| kept_log(&old));
    let text = match log {
        Some(log) => format!("{text}\n{log}"),
        None => text,
    };
    std::fs::write(&path, text)?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// The hand-written part of docs/verification.md: from its first `## ` heading to the end.
fn kept_log(page: &str) -> Option<String> {
    let at = if page.starts_with("## ") { Some(0) } else { page.find("\n## ").map(|k| k + 1) };
    at.map(|k| page[k..].to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_after_the_table_is_kept() {
        let page = "# Verification\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n## Log\n\ntext\n";
        assert_eq!(kept_log(page).as_deref(), Some("## Log\n\ntext\n"));
        assert_eq!(kept_log("# Verification\n\n| a |\n"), None);
    }

    #[test]
    fn clock_format() {
        assert_eq!(hms(0.0), "0:00:00");
        assert_eq!(hms(59.6), "0:01:00");
        assert_eq!(hms(3725.4), "1:02:05");
        assert_eq!(hms(-3.0), "0:00:00");
    }

    #[test]
    fn markdown_escapes_bars_in_metric_names() {
        let rows = vec![Row {
            case: "a/b".into(),
            metric: flexmpc_verification::Metric::at_most("max |x|", 1.0, 2.0),
            seconds: 0.5,
        }];
        let t = markdown_table(&rows);
        assert!(t.contains("max \\|x\\|"), "{t}");
        assert_eq!(t.lines().nth(2).unwrap().matches(" | ").count(), 5, "{t}");
    }
}
