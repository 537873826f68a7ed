//! Two runs of the same scene give identical output files.
//!
//! Each command runs twice, into two fresh folders, on a small configuration (the shipped 2D
//! NMPC scene with 8 elements per link instead of 50, 1 s of motion; the closed loop, its
//! modes, report and figures are the same code as the full scene's). With `--no-timings` the
//! two folders must be byte-identical, file for file; with timings, every file except the
//! timing files (`timings.json`, `timings.csv`, `solve_times.svg`) must be, and no other file
//! may hold a measured time. A sweep run with 1 and with 2 worker threads must write the same
//! files (results are ordered by input, not by completion), and `ocp --export` the same
//! problem.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

const TIMING_FILES: [&str; 3] = ["timings.json", "timings.csv", "solve_times.svg"];

/// A fresh work folder with the small scene; returns `(scene, folder)`.
fn setup(tag: &str) -> (PathBuf, PathBuf) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = std::fs::read_to_string(root.join("scenes/paper-2d-mpc.toml")).unwrap();
    assert_eq!(text.matches("elements = 50").count(), 2);
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("reproducible-{tag}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("small-2d.toml");
    std::fs::write(&scene, text.replace("elements = 50", "elements = 8")).unwrap();
    (scene, dir)
}

/// Runs `flexmpc` with `args` (the scene and `--out` are added by the caller).
fn run(args: &[&str], scene: &Path, out_flag: &str, out: &Path) {
    let o = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
        .arg("--quiet")
        .args(args)
        .arg(scene)
        .arg(out_flag)
        .arg(out)
        .output()
        .expect("the binary runs");
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
}

/// Every file under `dir` (relative path → bytes).
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(base: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(base, &p, out);
            } else {
                let rel = p.strip_prefix(base).unwrap().to_string_lossy().replace('\\', "/");
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn is_timing(rel: &str) -> bool {
    TIMING_FILES.contains(&rel)
}

/// The two folders hold the same file names, and the same bytes in every non-timing file.
fn assert_same(a: &Path, b: &Path, expect_timings: bool) {
    let (fa, fb) = (files(a), files(b));
    assert_eq!(
        fa.keys().collect::<Vec<_>>(),
        fb.keys().collect::<Vec<_>>(),
        "{} and {} hold different files",
        a.display(),
        b.display()
    );
    for t in TIMING_FILES {
        assert_eq!(fa.contains_key(t), expect_timings, "{t} in {}", a.display());
    }
    for (name, bytes) in &fa {
        if expect_timings && is_timing(name) {
            continue;
        }
        assert!(bytes == &fb[name], "{name} differs between {} and {}", a.display(), b.display());
        // no measured time outside the timing files
        if !is_timing(name) {
            let text = String::from_utf8_lossy(bytes);
            // the keys of the measured times (the report's link `solve_times.svg` is fine)
            for key in [
                "solve_time_s",
                "solve_time\"",
                "solve_time_median",
                "solve_time_worst",
                "wall_time",
            ] {
                assert!(!text.contains(key), "{name} holds a measured time (`{key}`)");
            }
        }
    }
}

/// `with` (a run with timings) holds the files of `without` (the same run with
/// `--no-timings`) with the same bytes, except the files of `except`, plus the timing files.
fn assert_only_timings_added(without: &Path, with: &Path, except: &[&str]) {
    let (fa, fc) = (files(without), files(with));
    let mut names: Vec<&String> = fa.keys().collect();
    let timing: Vec<String> = TIMING_FILES.iter().map(|t| t.to_string()).collect();
    names.extend(&timing);
    names.sort();
    assert_eq!(fc.keys().collect::<Vec<_>>(), names, "timings add exactly {TIMING_FILES:?}");
    for (name, bytes) in &fa {
        if !except.contains(&name.as_str()) {
            assert!(bytes == &fc[name], "{name} depends on --no-timings");
        }
    }
}

/// `flexmpc mpc`: byte-identical folders with `--no-timings`; with timings, identical apart
/// from the timing files, which hold one solve time per sample.
#[test]
fn mpc_twice_gives_identical_files() {
    let (scene, dir) = setup("mpc");
    let args = ["mpc", "--duration", "1"];
    let quiet: Vec<&str> = ["--no-timings"].iter().chain(&args).copied().collect();
    run(&quiet, &scene, "--out", &dir.join("a"));
    run(&quiet, &scene, "--out", &dir.join("b"));
    assert_same(&dir.join("a"), &dir.join("b"), false);
    assert!(files(&dir.join("a")).len() >= 12, "report, data and mode figures");

    run(&args, &scene, "--out", &dir.join("c"));
    run(&args, &scene, "--out", &dir.join("d"));
    assert_same(&dir.join("c"), &dir.join("d"), true);
    // timings add files and the report's links to them, nothing else
    assert_only_timings_added(&dir.join("a"), &dir.join("c"), &["index.html"]);
    let fc = files(&dir.join("c"));
    let t: serde_json::Value =
        serde_json::from_slice(&fc["timings.json"]).expect("timings.json is JSON");
    let samples = t["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 5, "one solve per τs = 0.2 s over 1 s");
    assert!(samples.iter().all(|s| s["solve_time_s"].as_f64().is_some_and(|x| x > 0.0)));
    let worst = t["solve_time_worst_s"].as_f64().unwrap();
    assert!(samples.iter().all(|s| s["solve_time_s"].as_f64().unwrap() <= worst));
    // --no-timings over an old folder removes the stale timing files
    run(&quiet, &scene, "--out", &dir.join("c"));
    assert_same(&dir.join("a"), &dir.join("c"), false);
}

/// `flexmpc sweep` over two ω0 and both controllers, once on one worker thread and once on
/// two: the same files (runs ordered by input, not by completion), no timings outside the
/// timing files.
#[test]
fn sweep_is_reproducible_across_thread_counts() {
    let (scene, dir) = setup("sweep");
    let args = ["sweep", "--omega0", "0.5,1", "--controller", "nmpc,lmpc", "--duration", "0.6"];
    for (threads, name) in [("1", "a"), ("2", "b")] {
        let a: Vec<&str> =
            ["--threads", threads, "--no-timings"].iter().chain(&args).copied().collect();
        run(&a, &scene, "--out", &dir.join(name));
    }
    assert_same(&dir.join("a"), &dir.join("b"), false);
    let f = files(&dir.join("a"));
    for name in ["sweep.csv", "sweep.json", "cost.svg", "inputs.svg", "snapshots.svg", "index.html"]
    {
        assert!(f.contains_key(name), "{name} missing");
    }
    assert!(f.contains_key("runs/lmpc-w0.5.csv") && f.contains_key("runs/nmpc-w1-snapshots.svg"));
    run(&args, &scene, "--out", &dir.join("c"));
    assert_only_timings_added(&dir.join("a"), &dir.join("c"), &["index.html"]);
}

/// `flexmpc ocp --export`: the exported problem is the same twice.
#[test]
fn ocp_export_is_reproducible() {
    let (scene, dir) = setup("ocp");
    let args = ["--no-timings", "ocp", "--controller", "lmpc", "--omega0", "0.5"];
    run(&args, &scene, "--export", &dir.join("a"));
    run(&args, &scene, "--export", &dir.join("b"));
    assert_same(&dir.join("a"), &dir.join("b"), false);
    assert!(files(&dir.join("a")).contains_key("ocp.json"));
}

/// `flexmpc simulate` (time series and plot) and `flexmpc modes` (mode figures at three
/// angles) hold no measured time: their folders are identical twice, without any flag.
#[test]
fn simulate_and_modes_are_reproducible() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("reproducible-simulate");
    let _ = std::fs::remove_dir_all(&dir);
    for name in ["a", "b"] {
        let sim: Vec<&str> = vec!["simulate", "--duration", "0.2"];
        run(&sim, &root.join("scenes/l-frame.toml"), "--out", &dir.join(name).join("sim"));
        run(
            &["modes"],
            &root.join("scenes/paper-2d-modes.toml"),
            "--out",
            &dir.join(name).join("modes"),
        );
    }
    let (fa, fb) = (files(&dir.join("a")), files(&dir.join("b")));
    assert!(
        fa.contains_key("sim/timeseries.csv") && fa.contains_key("sim/plot.svg"),
        "{:?}",
        fa.keys()
    );
    assert!(fa.contains_key("modes/angle-45/shapes.svg"), "{:?}", fa.keys());
    assert_same(&dir.join("a"), &dir.join("b"), false);
    assert_eq!(fa.len(), fb.len());
}
