//! End-to-end tests of the `flexmpc` binary.

use std::path::PathBuf;
use std::process::Command;

fn flexmpc() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_flexmpc"));
    c.current_dir(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.."));
    c.env_remove("RUST_BACKTRACE");
    c
}

fn modes_json(args: &[&str]) -> serde_json::Value {
    let dir =
        std::env::temp_dir().join(format!("flexmpc-modes-{}", args.join("_").replace('/', "-")));
    let out = flexmpc()
        .args(["modes", "--json", "--out", dir.to_str().unwrap()])
        .args(args)
        .output()
        .expect("the binary runs");
    assert!(out.status.success(), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join("components.svg").exists() && dir.join("shapes.svg").exists());
    serde_json::from_slice(&out.stdout).expect("stdout is JSON")
}

fn labels(v: &serde_json::Value) -> Vec<String> {
    v["labels"].as_array().unwrap().iter().map(|l| l.as_str().unwrap().to_string()).collect()
}

/// Paper §5.1: at 0° the first five elastic modes are 4 bending + 1 axial; rigid modes first.
#[test]
fn modes_of_the_paper_2d_two_link_at_0_deg() {
    let v = modes_json(&["scenes/paper-2d.toml", "--angle", "0", "--modes", "7"]);
    let l = labels(&v);
    assert_eq!(l.len(), 7);
    assert_eq!(&l[..2], ["rigid", "rigid"]);
    assert_eq!(l[2..].iter().filter(|x| *x == "bending").count(), 4);
    assert_eq!(l[2..].iter().filter(|x| *x == "axial").count(), 1);
    let w: Vec<f64> =
        v["frequencies_rad_s"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    assert!(w.windows(2).all(|p| p[0] <= p[1]), "frequencies ascend: {w:?}");
    assert!(w[..2].iter().all(|x| x.abs() < 1e-6) && w[2] > 1.0);
}

/// At 45° axial and bending motions mix (paper §5.1, Fig. 4b).
#[test]
fn modes_mix_at_45_deg() {
    let v = modes_json(&["scenes/paper-2d.toml", "--angle", "45", "--modes", "7"]);
    assert!(labels(&v)[2..].iter().any(|x| x == "mixed"), "{:?}", labels(&v));
}

/// The 3D two-link (universal joints) has four rigid modes.
#[test]
fn modes_of_the_paper_3d_two_link() {
    let v = modes_json(&["scenes/paper-3d.toml", "--modes", "6"]);
    assert_eq!(v["n_rigid"].as_u64(), Some(4));
}

/// `--angle` on a scene without a joint-attached beam is an error naming the field.
#[test]
fn angle_without_joint_is_a_clear_error() {
    let out =
        flexmpc().args(["modes", "scenes/cantilever.toml", "--angle", "10"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("scenes/cantilever.toml") && err.contains("beams.attach"), "{err}");
}

/// The shipped 2D NMPC scene with 8 elements per link instead of 50 (a fast closed loop:
/// the same inputs, mode set, weights and timing), written to a fresh folder.
fn small_2d_scene(tag: &str) -> (PathBuf, PathBuf) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = std::fs::read_to_string(root.join("scenes/paper-2d-mpc.toml")).unwrap();
    assert_eq!(text.matches("elements = 50").count(), 2);
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-{tag}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("small-2d.toml");
    std::fs::write(&scene, text.replace("elements = 50", "elements = 8")).unwrap();
    (scene, dir.join("out"))
}

const SUMMARY_KEYS: [&str; 10] = [
    "omega0",
    "controller",
    "plant",
    "v_ratio_final",
    "max_joint_angle_deg",
    "orientation_error_deg",
    "rigid_rate_ratio",
    "stabilised",
    "solve_time_worst_s",
    "solve_time_median_s",
];

fn assert_summary_shape(v: &serde_json::Value) {
    for k in SUMMARY_KEYS {
        assert!(v.get(k).is_some(), "summary lacks `{k}`: {v}");
    }
    for k in ["v_ratio_final", "max_joint_angle_deg", "rigid_rate_ratio", "solve_time_worst_s"] {
        let x = v[k].as_f64().unwrap_or_else(|| panic!("`{k}` is not a number: {v}"));
        assert!(x.is_finite() && x >= 0.0, "`{k}` = {x}");
    }
    assert!(v["stabilised"].is_boolean());
}

/// `flexmpc mpc` on a short loop: the JSON summary on stdout (and only that), the
/// CSV time series (a row every 0.05 s), the per-sample solver log (one entry per τs) and the
/// report folder.
#[test]
fn mpc_short_run_writes_csv_solver_log_and_report() {
    let (scene, out) = small_2d_scene("mpc");
    let o = flexmpc()
        .args(["--json", "mpc"])
        .arg(&scene)
        .args(["--duration", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is only JSON");
    assert_summary_shape(&v);
    assert_eq!(v["controller"], "nmpc");
    assert_eq!(v["plant"], "fe");
    assert_eq!(v["omega0"].as_f64(), Some(1.0));
    // a rotating structure: the joints move, and the report says how much
    assert!(v["max_joint_angle_deg"].as_f64().unwrap() > 1.0, "{v}");
    let csv = std::fs::read_to_string(out.join("timeseries.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 1 + 21, "header + t = 0, 0.05, …, 1.0");
    assert!(lines[0].starts_with("t,v_state,v_ratio,u:torque:root,u:tip-axial,u:tip-transverse"));
    let samples: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("samples.json")).unwrap()).unwrap();
    let samples = samples.as_array().unwrap();
    assert_eq!(samples.len(), 5, "one solve per τs = 0.2 s over 1 s");
    for s in samples {
        for k in ["t", "status", "strategy", "iterations", "line_search_trials", "u"] {
            assert!(s.get(k).is_some(), "sample lacks `{k}`: {s}");
        }
        assert!(s.get("solve_time").is_none(), "measured times go to timings.json: {s}");
        assert!(s["u"].as_array().unwrap().iter().all(|u| u.as_f64().unwrap().abs() <= 5.0));
    }
    // the solve times per sample are in the timing files
    let timings: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("timings.json")).unwrap()).unwrap();
    assert_eq!(timings["samples"].as_array().unwrap().len(), 5);
    assert_eq!(timings["sampling_s"].as_f64(), Some(0.2));
    let worst = timings["solve_time_worst_s"].as_f64().unwrap();
    assert_eq!(v["solve_time_worst_s"].as_f64(), Some(worst), "stdout and timings.json agree");
    for f in ["index.html", "cost.svg", "inputs.svg", "snapshots.svg", "summary.json"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
}

/// `flexmpc mpc --repeat 2`: the same outputs as one run (the repetition agrees apart from
/// its timings), each sample's times the smaller of the two measurements, and the work counts
/// per sample in `timings.csv`; `--repeat 0` is refused.
#[test]
fn mpc_repeat_keeps_the_outputs_and_the_fastest_times() {
    let (scene, out) = small_2d_scene("repeat");
    let run = |dir: &str, repeat: &str| {
        let o = flexmpc()
            .args(["--json", "mpc"])
            .arg(&scene)
            .args(["--duration", "0.4", "--repeat", repeat, "--out"])
            .arg(out.join(dir))
            .output()
            .unwrap();
        assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).expect("stdout is only JSON")
    };
    let (one, two) = (run("one", "1"), run("two", "2"));
    for f in ["summary.json", "samples.json", "timeseries.csv"] {
        let read = |d: &str| std::fs::read(out.join(d).join(f)).unwrap();
        assert_eq!(read("one"), read("two"), "{f}");
    }
    assert_eq!(one["v_ratio_final"], two["v_ratio_final"]);
    let csv = std::fs::read_to_string(out.join("two/timings.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (rhs, jac) = (col("rhs_evaluations"), col("jacobian_evaluations"));
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let count = |i: usize| f[i].parse::<usize>().unwrap();
        assert!(count(rhs) + count(jac) > 0, "a sample evaluates the model: {line}");
    }
    let o = flexmpc().args(["mpc"]).arg(&scene).args(["--repeat", "0"]).output().unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--repeat"));
}

/// `flexmpc mpc --model exact-joints` on the paper's 2D scene (2 × 8 elements, 1 s): the
/// NMPC on the exact-joints model runs on the FE plant, writes its summary into a folder of
/// its own (`nmpc-exact-fe-w1`, next to the paper model's `nmpc-fe-w1`), and slows the spin;
/// `ocp` with it solves the closed loop's first sample (same first control) and `ocp --export`
/// writes the exact-joints model's export; an LMPC with it is a clear error naming the model.
#[test]
fn mpc_with_the_exact_joints_model() {
    let (scene, out) = small_2d_scene("mpc-exact");
    let dir = out.parent().unwrap().to_path_buf();
    let o = flexmpc()
        .current_dir(&dir)
        .args(["--json", "mpc"])
        .arg(&scene)
        .args(["--model", "exact-joints", "--duration", "1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is only JSON");
    assert_summary_shape(&v);
    assert_eq!(v["controller"], "nmpc");
    assert_eq!(v["model"], "exact-joints");
    assert!(v["error"].is_null(), "{v}");
    assert!(v["rigid_rate_ratio"].as_f64().unwrap() < 0.5, "{v}");
    let folder = dir.join("out/small-2d/nmpc-exact-fe-w1");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["v_ratio_final"], v["v_ratio_final"]);
    assert!(!dir.join("out/small-2d/nmpc-fe-w1").exists());
    // the first sample alone: the closed loop's first control
    let o = flexmpc()
        .current_dir(&dir)
        .args(["--json", "ocp"])
        .arg(&scene)
        .args(["--model", "exact-joints"])
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let first: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is only JSON");
    assert_eq!(first["model"], "exact-joints");
    let samples: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("samples.json")).unwrap())
            .unwrap();
    assert_eq!(first["first_control"], samples[0]["u"], "{first}");
    assert_eq!(first["controls"].as_array().unwrap().len(), 24, "Nc = 24");
    assert!(first["cost"].as_f64().unwrap().is_finite(), "{first}");
    // its export: the exact-joints model's own format, the same initial state
    let o = flexmpc()
        .current_dir(&dir)
        .args(["--json", "ocp"])
        .arg(&scene)
        .args(["--model", "exact-joints", "--export", "ocp-exact"])
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join("ocp-exact").join(f)).unwrap())
            .unwrap()
    };
    let (model, ocp) = (read("model.json"), read("ocp.json"));
    assert_eq!(model["format"], "flexmpc-exact-joints-rom");
    assert_eq!(ocp["model"], "exact-joints");
    assert_eq!(ocp["x0"].as_array().unwrap().len(), first["n_state"].as_u64().unwrap() as usize);
    assert_eq!(model["n_state"], first["n_state"]);
    // the linear MPC has no exact-joints form: a clear error naming the setting
    let o = flexmpc()
        .current_dir(&dir)
        .arg("mpc")
        .arg(&scene)
        .args(["--model", "exact-joints", "--controller", "lmpc"])
        .output()
        .unwrap();
    assert!(!o.status.success(), "mpc --model exact-joints --controller lmpc succeeded");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("kind"), "{err}");
}

/// `flexmpc sweep` with two ω0 in parallel (`--threads 2`): results in input order, one CSV
/// row each, the Fig. 6-style plot; a larger disturbance bends the elbow more.
#[test]
fn sweep_two_omegas_in_parallel() {
    let (scene, out) = small_2d_scene("sweep");
    let o = flexmpc()
        .args(["--json", "--threads", "2", "sweep"])
        .arg(&scene)
        .args(["--omega0", "0.25,0.75", "--controller", "lmpc", "--duration", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is only JSON");
    let runs = v.as_array().expect("an array of runs");
    assert_eq!(runs.len(), 2);
    for r in runs {
        assert_summary_shape(r);
        assert_eq!(r["controller"], "lmpc");
    }
    assert_eq!(runs[0]["omega0"].as_f64(), Some(0.25));
    assert_eq!(runs[1]["omega0"].as_f64(), Some(0.75));
    let j = |i: usize| runs[i]["max_joint_angle_deg"].as_f64().unwrap();
    assert!(j(1) > j(0), "elbow {} (ω0 = 0.75) vs {} (ω0 = 0.25)", j(1), j(0));
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3);
    assert!(out.join("cost.svg").exists() && out.join("runs/lmpc-w0.25.csv").exists());
    // Fig. 10 (inputs), Figs. 7/9 (snapshots), solve time per sample against τs
    for f in ["inputs.svg", "snapshots.svg", "solve_times.svg", "runs/lmpc-w0.75-snapshots.svg"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let solve = std::fs::read_to_string(out.join("solve_times.svg")).unwrap();
    assert!(solve.contains("τs = 0.2 s") && solve.contains("goal 50 ms"), "reference lines");
    let t = std::fs::read_to_string(out.join("timings.csv")).unwrap();
    assert_eq!(t.lines().count(), 3, "header + one row per run: {t}");
}

/// `--quiet`: nothing on stdout or stderr for a successful run.
#[test]
fn quiet_prints_nothing() {
    let (scene, out) = small_2d_scene("quiet");
    let o = flexmpc()
        .args(["--quiet", "mpc"])
        .arg(&scene)
        .args(["--duration", "0.4", "--controller", "lmpc", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    assert!(o.stdout.is_empty(), "stdout: {}", String::from_utf8_lossy(&o.stdout));
    assert!(o.stderr.is_empty(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("index.html").exists());
    let o = flexmpc().args(["check", "--quiet"]).arg(&scene).output().unwrap();
    assert!(o.status.success() && o.stdout.is_empty() && o.stderr.is_empty());
}

/// `check --json` describes the scene, its control inputs included.
#[test]
fn check_json_shape() {
    let o = flexmpc().args(["check", "--json", "scenes/paper-3d-mpc.toml"]).output().unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["ok"], true);
    assert_eq!(v["beams"].as_u64(), Some(2));
    assert_eq!(v["controlled"], true);
    assert_eq!(v["control_inputs"].as_u64(), Some(5));
}

/// `mpc` on a scene without `[scenario]` says what is missing.
#[test]
fn mpc_without_scenario_is_a_clear_error() {
    let o = flexmpc().args(["mpc", "scenes/cantilever.toml"]).output().unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("scenes/cantilever.toml") && err.contains("[scenario]"), "{err}");
}

/// `[modes] angles = [0, 45, 90]`: `flexmpc modes` computes all three (paper Figs. 4–5): pure
/// axial and bending modes at 0°, mixed ones at 45°.
#[test]
fn modes_at_the_scene_angles() {
    let dir = std::env::temp_dir().join("flexmpc-modes-angles");
    let o = flexmpc()
        .args(["modes", "--json", "scenes/paper-2d-modes.toml", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let a = v["angles"].as_array().unwrap();
    assert_eq!(a.len(), 3);
    let angles: Vec<f64> = a.iter().map(|x| x["angle_deg"].as_f64().unwrap()).collect();
    assert_eq!(angles, [0.0, 45.0, 90.0]);
    assert!(!labels(&a[0]).iter().any(|l| l == "mixed"), "{:?}", labels(&a[0]));
    assert!(labels(&a[1]).iter().any(|l| l == "mixed"), "{:?}", labels(&a[1]));
    assert_eq!(labels(&a[0]).len(), 7, "[modes] count = 7");
    assert!(dir.join("angle-45/shapes.svg").exists());
}

/// `flexmpc ocp --json --export`: the first sample's problem alone — Nc controls within the
/// bounds, a finite positive cost — and its export (ocp.json with the same initial state size).
#[test]
fn ocp_first_sample_and_export() {
    let (scene, out) = small_2d_scene("ocp");
    let o = flexmpc()
        .args(["--json", "ocp"])
        .arg(&scene)
        .args(["--controller", "lmpc", "--omega0", "0.5", "--export"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["controller"], "lmpc");
    let cost = v["cost"].as_f64().unwrap();
    assert!(cost.is_finite() && cost > 0.0, "{v}");
    let controls = v["controls"].as_array().unwrap();
    assert_eq!(controls.len(), 24, "Nc = 24");
    for u in controls {
        let u = u.as_array().unwrap();
        assert_eq!(u.len(), 3);
        assert!(u.iter().all(|x| x.as_f64().unwrap().abs() <= 5.0 + 1e-9));
    }
    let ocp: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ocp.json")).unwrap()).unwrap();
    assert_eq!(ocp["x0"].as_array().unwrap().len() as u64, v["n_state"].as_u64().unwrap());
    assert_eq!(ocp["omega0"].as_f64(), Some(0.5));
}

/// Every shipped scene runs from the CLI (shortened: the full runs are `cargo run`
/// and `cargo xtask` material). Closed-loop scenes run `mpc` for two samples; the others
/// `simulate` for 20 ms; a scene with `[modes] angles` also runs `modes`.
#[test]
fn every_shipped_scene_runs_from_the_cli() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(root.join("scenes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    scenes.sort();
    assert!(scenes.len() >= 8, "shipped scenes: {scenes:?}");
    for path in &scenes {
        let text = std::fs::read_to_string(path).unwrap();
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let out = std::env::temp_dir().join(format!("flexmpc-shipped-{stem}"));
        let rel = format!("scenes/{stem}.toml");
        let mut runs: Vec<Vec<String>> = Vec::new();
        if text.contains("[scenario]") {
            runs.push(
                ["mpc", &rel, "--duration", "0.4", "--out", out.to_str().unwrap(), "--json"]
                    .map(String::from)
                    .to_vec(),
            );
        } else {
            runs.push(
                ["simulate", &rel, "--duration", "0.02", "--out", out.to_str().unwrap(), "--json"]
                    .map(String::from)
                    .to_vec(),
            );
        }
        if text.contains("angles") {
            runs.push(
                ["modes", &rel, "--out", out.join("modes").to_str().unwrap(), "--json"]
                    .map(String::from)
                    .to_vec(),
            );
        }
        for args in runs {
            let o = flexmpc().args(&args).output().expect("the binary runs");
            assert!(o.status.success(), "{args:?} failed: {}", String::from_utf8_lossy(&o.stderr));
            let v: serde_json::Value = serde_json::from_slice(&o.stdout)
                .unwrap_or_else(|e| panic!("{args:?}: stdout is not JSON ({e})"));
            assert!(!v.is_null(), "{args:?}: empty JSON");
        }
    }
}

/// Without `--out`, every variant of a closed loop has its own folder
/// `out/<scene>/<controller>-<plant>-w<ω0>/` (relative to the working directory): runs with
/// another controller, plant or ω0 never overwrite each other; a sweep has its own too.
#[test]
fn default_output_folders_are_per_variant() {
    let (scene, work) = small_2d_scene("variants");
    std::fs::create_dir_all(&work).unwrap();
    let variants: [&[&str]; 3] = [
        &["--controller", "lmpc", "--omega0", "0.5"],
        &["--controller", "nmpc", "--omega0", "0.5"],
        &["--controller", "lmpc", "--omega0", "0.75", "--plant", "rom"],
    ];
    for v in variants {
        let o = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
            .current_dir(&work)
            .args(["--quiet", "--no-timings", "mpc"])
            .arg(&scene)
            .args(["--duration", "0.4"])
            .args(v)
            .output()
            .unwrap();
        assert!(o.status.success(), "{v:?}: {}", String::from_utf8_lossy(&o.stderr));
    }
    let base = work.join("out/small-2d");
    for (dir, ctrl, plant, w) in [
        ("lmpc-fe-w0.5", "lmpc", "fe", 0.5),
        ("nmpc-fe-w0.5", "nmpc", "fe", 0.5),
        ("lmpc-rom-w0.75", "lmpc", "rom", 0.75),
    ] {
        let s: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(base.join(dir).join("summary.json"))
                .unwrap_or_else(|e| panic!("{dir}: {e}")),
        )
        .unwrap();
        assert_eq!((s["controller"].as_str(), s["plant"].as_str()), (Some(ctrl), Some(plant)));
        assert_eq!(s["omega0"].as_f64(), Some(w));
        assert!(base.join(dir).join("index.html").exists());
    }
    let o = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
        .current_dir(&work)
        .args(["--quiet", "--no-timings", "sweep"])
        .arg(&scene)
        .args(["--duration", "0.4", "--omega0", "0.25,0.5", "--controller", "lmpc"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(base.join("sweep-lmpc-fe-w0.25_0.5/sweep.csv").exists());
}

/// `flexmpc sweep --model paper,exact-joints` (2D, 2 × 8 elements, 1 s, two ω0): both models'
/// runs in one sweep, models outer, the `model` column in `sweep.csv`, the exact-joints runs
/// under their own file names, both models in the legend of `cost.svg`; the paper model's
/// runs are the same as those of the single-model sweep.
#[test]
fn sweep_of_both_models() {
    let (scene, out) = small_2d_scene("sweep-models");
    let dir = out.parent().unwrap().to_path_buf();
    let sweep = |models: &str| {
        let o = flexmpc()
            .current_dir(&dir)
            .args(["--json", "--no-timings", "sweep"])
            .arg(&scene)
            .args(["--model", models, "--controller", "nmpc", "--omega0", "0.5,1"])
            .args(["--duration", "1"])
            .output()
            .unwrap();
        assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is only JSON");
        v.as_array().expect("an array of runs").clone()
    };
    let both = sweep("paper,exact-joints");
    let models: Vec<&str> = both.iter().map(|r| r["model"].as_str().unwrap()).collect();
    assert_eq!(models, ["paper", "paper", "exact-joints", "exact-joints"]);
    for r in &both {
        assert!(r["error"].is_null(), "{r}");
    }
    let folder = dir.join("out/small-2d/sweep-nmpc-paper+exact-joints-fe-w0.5_1");
    let csv = std::fs::read_to_string(folder.join("sweep.csv")).unwrap();
    assert!(csv.lines().next().unwrap().starts_with("controller,model,plant,omega0"), "{csv}");
    assert_eq!(csv.lines().filter(|l| l.starts_with("nmpc,exact-joints,fe,")).count(), 2);
    for f in ["runs/nmpc-w0.5.csv", "runs/nmpc-exact-w1.csv", "runs/nmpc-exact-w1-snapshots.svg"] {
        assert!(folder.join(f).exists(), "{f} missing");
    }
    let cost = std::fs::read_to_string(folder.join("cost.svg")).unwrap();
    assert!(cost.contains("paper model (solid)") && cost.contains("exact-joints model (dashed)"));
    let paper = sweep("paper");
    assert_eq!(paper.len(), 2);
    for (a, b) in paper.iter().zip(&both) {
        assert_eq!(a["v_ratio_final"], b["v_ratio_final"], "{a} vs {b}");
    }
}
