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
