//! The `flexmpc` binary under conditions a researcher meets: a closed pipe, `RUST_BACKTRACE`,
//! names that need quoting in CSV, a mesh too large for the dense modal basis. None of them
//! may panic.

use std::path::PathBuf;
use std::process::{Command, Stdio};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn flexmpc() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_flexmpc"));
    c.current_dir(root());
    c.env_remove("RUST_BACKTRACE");
    c
}

fn scratch(tag: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("breaks-{tag}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `flexmpc modes … | head -1`: the reader closes the pipe before flexmpc writes; the run ends
/// quietly (exit 0, nothing on stderr), with and without `--json`.
#[test]
fn closed_stdout_ends_quietly() {
    let dir = scratch("pipe");
    for json in [false, true] {
        let mut c = flexmpc();
        c.args(["modes", "scenes/paper-2d-modes.toml", "--out"]).arg(dir.join("modes"));
        if json {
            c.arg("--json");
        }
        let mut child =
            c.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("the binary runs");
        // close the read end at once: every write to stdout meets a broken pipe
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "json = {json}: {err}");
        assert_eq!(o.status.code(), Some(0), "json = {json}: {err}");
        assert!(err.is_empty(), "json = {json}: stderr `{err}`");
    }
}

/// With `RUST_BACKTRACE=1` a user error is still its message chain, one line each: no stack
/// trace.
#[test]
fn user_errors_have_no_backtrace() {
    let dir = scratch("user-error");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "components = \"planar\"\n[[beams]]\nname = \"b\"\nlength = -1.0\n")
        .unwrap();
    for args in [
        vec!["check".to_string(), "scenes/no-such-scene.toml".to_string()],
        vec!["check".to_string(), bad.display().to_string()],
        vec!["mpc".to_string(), "scenes/cantilever.toml".to_string()],
    ] {
        for bt in ["1", "full"] {
            let o = flexmpc().env("RUST_BACKTRACE", bt).args(&args).output().unwrap();
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
            assert!(err.starts_with("error: "), "{args:?}: {err}");
            assert!(!err.to_lowercase().contains("backtrace"), "{args:?}: {err}");
            let lines = err.lines().count();
            assert!(lines <= 4, "{args:?}: {lines} lines: {err}");
        }
    }
}

/// A beam named `my,beam` keeps the CSV rectangular: the header field is quoted, every row
/// has as many fields as the header, and the column is found by its name.
#[test]
fn names_with_commas_keep_the_csv_rectangular() {
    let dir = scratch("comma");
    let text =
        std::fs::read_to_string(root().join("crates/flexmpc/tests/fixtures/cantilever-10.toml"))
            .unwrap()
            .replace("name = \"beam\"", "name = \"my,beam\"")
            .replace("end = \"beam:start\"", "end = \"my,beam:start\"")
            .replace("beam = \"beam\"", "beam = \"my,beam\"");
    let scene = dir.join("comma.toml");
    std::fs::write(&scene, text).unwrap();
    let out = dir.join("out");
    let o = flexmpc()
        .args(["--quiet", "simulate"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut r = csv::Reader::from_path(out.join("timeseries.csv")).unwrap();
    let header = r.headers().unwrap().clone();
    let col = header.iter().position(|h| h == "my,beam.end.z").expect("the column by its name");
    let mut rows = 0;
    for rec in r.records() {
        let rec = rec.expect("a well-formed row");
        assert_eq!(rec.len(), header.len());
        let z: f64 = rec[col].parse().unwrap();
        assert!(z.is_finite() && z <= 0.0, "the tip moves down under its load: {z}");
        rows += 1;
    }
    assert_eq!(rows, 11, "t = 0 and every 5 ms to 0.05 s");
}

/// `modes` on a mesh of 100,000 elements, whose dense modal basis would need terabytes: the
/// sparse route gives its lowest modes (the same as on a coarse mesh), no panic; `check`
/// warns that the dense basis of `mpc`, `sweep` and `ocp` would not fit.
#[test]
fn huge_mesh_modes_take_the_sparse_route() {
    let dir = scratch("huge");
    let text = std::fs::read_to_string(root().join("scenes/paper-2d-modes.toml"))
        .unwrap()
        .replace("elements = 50", "elements = 50000");
    let scene = dir.join("huge.toml");
    std::fs::write(&scene, text).unwrap();
    let o = flexmpc().args(["check", "--json"]).arg(&scene).output().unwrap();
    assert!(o.status.success(), "check accepts it: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["modal_basis_fits"], false, "check warns: {v}");
    let o = flexmpc()
        .args(["modes", "--json", "--angle", "0", "--modes", "3"])
        .arg(&scene)
        .arg("--out")
        .arg(dir.join("modes"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let w: Vec<f64> =
        v["frequencies_rad_s"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    assert_eq!(w.len(), 3, "{v}");
    assert_eq!((w[0], w[1]), (0.0, 0.0), "two rigid modes: {w:?}");
    // the first elastic mode of the paper's 2D two-link at 0° (11.5125 rad/s at 2 × 50 and at
    // 2 × 2000 elements)
    assert!((w[2] - 11.5125).abs() < 1e-3, "{w:?}");
}
