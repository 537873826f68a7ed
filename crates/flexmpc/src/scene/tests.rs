//! Unit tests of the scene loader.

use super::*;

const BASE: &str = r#"description = "test"
components = "planar"

[sections.link]
preset = "paper-2d"

[[beams]]
name = "link1"
section = "link"
length = 1.0
elements = 4

[[beams]]
name = "link2"
section = "link"
length = 1.0
elements = 4
attach = { joint = "elbow", axis = [0.0, 1.0, 0.0], angle_deg = 30.0 }

[[joints]]
name = "elbow"
kind = "hinge"
ends = ["link1:end", "link2:start"]
axis = [0.0, 1.0, 0.0]

[[supports]]
name = "root"
end = "link1:start"
kind = "hinge"
axis = [0.0, 1.0, 0.0]

[[loads]]
beam = "link2"
node = "end"
frame = "follower"
force = [0.0, 0.0, 0.1]

[run]
dt = 1e-3
duration = 0.01
"#;

fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).expect("needle in text") + 1
}

/// Replaces `from` by `to` in the base scene, loads it, and checks that the error names
/// the file, the expected line (of `at`, in the modified text) and `field`.
fn expect_error(from: &str, to: &str, at: &str, field: &str) {
    assert!(BASE.contains(from), "base lacks {from}");
    let text = BASE.replacen(from, to, 1);
    let err = match check_str(Path::new("bad.toml"), &text) {
        Ok(_) => panic!("`{to}` was accepted"),
        Err(e) => e,
    };
    let msg = err.to_string();
    let line = line_of(&text, at);
    assert!(msg.starts_with(&format!("bad.toml:{line}:")), "expected line {line} in: {msg}");
    assert!(msg.contains(field), "expected field `{field}` in: {msg}");
}

#[test]
fn base_scene_builds_and_runs() {
    let s = load_str(Path::new("ok.toml"), BASE).unwrap();
    assert_eq!(s.steps, 10);
    let mut plant = s.plant().unwrap();
    for _ in 0..s.steps {
        plant.step().unwrap();
    }
    assert!((plant.joint_angles()[0] - 30f64.to_radians()).abs() < 0.01);
}

#[test]
fn malformed_scenes_name_file_line_and_field() {
    let l2 = "length = 1.0\nelements = 4\nattach";
    let elbow_ends = "ends = [\"link1:end\", \"link2:start\"]\naxis = [0.0, 1.0, 0.0]";
    // wrong type
    expect_error(
        "length = 1.0\nelements = 4\n\n[[beams]]",
        "length = \"one\"\nelements = 4\n\n[[beams]]",
        "length = \"one\"",
        "beams[0].length",
    );
    // unknown field (typo)
    expect_error("elements = 4\nattach", "elemnts = 4\nattach", "elemnts", "elemnts");
    // a beam rotation about a zero axis
    expect_error(
        "elements = 4\n\n[[beams]]",
        "elements = 4\nrotation = { axis = [0.0, 0.0, 0.0], angle_deg = 10.0 }\n\n[[beams]]",
        "rotation = {",
        "beams[0].rotation",
    );
    // a mesh too large to allocate
    expect_error(
        "elements = 4\nattach",
        "elements = 1000000\nattach",
        "elements = 1000000",
        "beams[1].elements",
    );
    // finite rates whose energy overflows
    expect_error(
        "[run]",
        "[[initial.rigid]]\nomega = [0.0, 1e200, 0.0]\n\n[run]",
        "[[initial.rigid]]",
        "initial.rigid",
    );
    // missing field
    expect_error("dt = 1e-3\n", "", "[run]", "dt");
    // unknown beam in a joint
    expect_error(
        "ends = [\"link1:end\", \"link2:start\"]",
        "ends = [\"link1:end\", \"link3:start\"]",
        "link3",
        "joints[0].ends",
    );
    // unknown end
    expect_error(
        "end = \"link1:start\"",
        "end = \"link1:middle\"",
        "link1:middle",
        "supports[0].end",
    );
    // negative length
    expect_error(l2, "length = -1.0\nelements = 4\nattach", "length = -1.0", "beams[1].length");
    // zero elements
    expect_error(l2, "length = 1.0\nelements = 0\nattach", "elements = 0", "beams[1].elements");
    // bad joint kind
    expect_error(
        "kind = \"hinge\"\nends",
        "kind = \"slider\"\nends",
        "kind = \"slider\"",
        "joints[0].kind",
    );
    // hinge without axis
    expect_error(
        elbow_ends,
        "ends = [\"link1:end\", \"link2:start\"]",
        "[[joints]]",
        "joints[0].axis",
    );
    // zero-length axis (found by the structure, attributed to the joint)
    expect_error(
        elbow_ends,
        "ends = [\"link1:end\", \"link2:start\"]\naxis = [0.0, 0.0, 0.0]",
        "[[joints]]",
        "joints[0]",
    );
    // planar hinge off e2
    expect_error(
        "kind = \"hinge\"\naxis = [0.0, 1.0, 0.0]\n\n[[loads]]",
        "kind = \"hinge\"\naxis = [1.0, 0.0, 0.0]\n\n[[loads]]",
        "[[supports]]",
        "supports[0]",
    );
    // end used twice
    expect_error("end = \"link1:start\"", "end = \"link1:end\"", "[[supports]]", "supports[0]");
    // unknown section
    expect_error(
        "section = \"link\"\nlength = 1.0\nelements = 4\nattach",
        "section = \"rod\"\nlength = 1.0\nelements = 4\nattach",
        "section = \"rod\"",
        "beams[1].section",
    );
    // bad preset
    expect_error(
        "preset = \"paper-2d\"",
        "preset = \"paper-4d\"",
        "paper-4d",
        "sections.link.preset",
    );
    // load on a node that does not exist
    expect_error("node = \"end\"", "node = 9", "node = 9", "loads[0].node");
    // bad load frame
    expect_error("frame = \"follower\"", "frame = \"body\"", "frame = \"body\"", "loads[0].frame");
    // non-positive time step
    expect_error("dt = 1e-3", "dt = 0.0", "dt = 0.0", "run.dt");
    // attach to an unknown joint
    expect_error("attach = { joint = \"elbow\"", "attach = { joint = \"knee\"", "knee", "beams[1]");
    // bad components
    expect_error("components = \"planar\"", "components = \"flat\"", "components", "components");
    // a support given a list of ends
    expect_error(
        "end = \"link1:start\"",
        "ends = [\"link1:start\"]",
        "[[supports]]",
        "supports[0].end",
    );
}

/// The closed-loop sections: each malformed value names its file, line and field.
#[test]
fn malformed_control_sections_name_file_line_and_field() {
    let base = format!(
        "{}{}",
        BASE.replace("force = [0.0, 0.0, 0.1]", "force = [0.0, 0.0, 1.0]\ncontrol = true"),
        r#"
[modes]
selection = "paper-2d"

[controller]
kind = "nmpc"
substeps = 16

[controller.weights]
ku = 0.1

[scenario]
axis = [0.0, 1.0, 0.0]
plant = "fe"
sampling = 0.2
duration = 1.0

[sweep]
omega0 = [0.5, 1.0]
controllers = ["nmpc"]
"#
    );
    let ok = load_str(Path::new("ok.toml"), &base).unwrap_or_else(|e| panic!("{e}"));
    let c = ok.control.expect("[scenario]");
    assert_eq!(c.sweep_omegas, [0.5, 1.0]);
    assert_eq!(c.scenario.inputs.len(), 1);
    let check = |from: &str, to: &str, at: &str, field: &str, allowed: &str| {
        assert!(base.contains(from), "base lacks {from}");
        let text = base.replacen(from, to, 1);
        let msg = match check_str(Path::new("bad.toml"), &text) {
            Ok(_) => panic!("`{to}` was accepted"),
            Err(e) => e.to_string(),
        };
        let line = line_of(&text, at);
        assert!(msg.starts_with(&format!("bad.toml:{line}:")), "line {line} in: {msg}");
        assert!(msg.contains(field), "field `{field}` in: {msg}");
        assert!(msg.contains(allowed), "`{allowed}` in: {msg}");
    };
    check(
        "kind = \"nmpc\"",
        "kind = \"pid\"",
        "kind = \"pid\"",
        "controller.kind",
        "`nmpc` or `lmpc`",
    );
    check(
        "plant = \"fe\"",
        "plant = \"beam\"",
        "plant = \"beam\"",
        "scenario.plant",
        "`fe` or `rom`",
    );
    check("ku = 0.1", "ku = -1.0", "ku = -1.0", "controller.weights.ku", "> 0");
    check("substeps = 16", "substeps = 0", "substeps = 0", "controller.substeps", "at least 1");
    check(
        "substeps = 16",
        "substeps = 16\nintegrator = \"implicit-midpoint\"\nnewton_tolerance = 0.5",
        "newton_tolerance = 0.5",
        "controller.newton_tolerance",
        "(0, 1e-2]",
    );
    check(
        "substeps = 16",
        "substeps = 16\nnewton_tolerance = 1e-8",
        "newton_tolerance = 1e-8",
        "controller.newton_tolerance",
        "implicit-midpoint",
    );
    check(
        "substeps = 16",
        "substeps = 16\nplan_joint_limit_deg = 200.0",
        "plan_joint_limit_deg = 200.0",
        "controller.plan_joint_limit_deg",
        "(0, 180]",
    );
    check(
        "substeps = 16",
        "substeps = 16\njoint_limit = false\nplan_joint_limit_deg = 25.0",
        "plan_joint_limit_deg = 25.0",
        "controller.plan_joint_limit_deg",
        "joint_limit = false",
    );
    check("sampling = 0.2", "sampling = 0.33", "sampling = 0.33", "scenario.sampling", "multiple");
    check("duration = 1.0", "duration = 1.01", "duration = 1.01", "scenario.duration", "multiple");
    check("sampling = 0.2", "sampling = 7.0", "sampling = 7.0", "scenario.sampling", "horizon");
    check(
        "axis = [0.0, 1.0, 0.0]\nplant",
        "axis = [0.0, 0.0, 0.0]\nplant",
        "axis = [0.0, 0.0, 0.0]",
        "scenario.axis",
        "non-zero",
    );
    check(
        "controllers = [\"nmpc\"]",
        "controllers = [\"lqr\"]",
        "controllers",
        "sweep.controllers",
        "`nmpc` or `lmpc`",
    );
    check("omega0 = [0.5, 1.0]", "omega0 = []", "omega0 = []", "sweep.omega0", "at least one");
    check(
        "selection = \"paper-2d\"",
        "selection = \"paper-2d\"\nlowest = 4",
        "selection = ",
        "modes.selection",
        "only one",
    );
    check(
        "selection = \"paper-2d\"",
        "selection = \"paper-9d\"",
        "selection",
        "modes.selection",
        "`paper-2d` or `paper-3d`",
    );
    check(
        "frame = \"follower\"",
        "frame = \"dead\"",
        "frame = \"dead\"",
        "loads[0].frame",
        "follower",
    );
    check(
        "force = [0.0, 0.0, 1.0]\ncontrol = true",
        "force = [0.0, 0.0, 1.0]",
        "[[loads]]",
        "loads[0].control",
        "control = true",
    );
    check("axis = [0.0, 1.0, 0.0]\nplant", "plant", "[scenario]", "axis", "missing");
    check(
        "[scenario]",
        "[scenario]\nroot = \"hip\"",
        "root = \"hip\"",
        "scenario.root",
        "supports: root",
    );
    check("[scenario]", "[scenario]\nspeed = 1.0", "speed", "speed", "unknown field");
    // keys of the library types the scene deserialises directly: [scenario] flattens
    // `mpc::Timing`, [controller.weights] is `mpc::CostWeights`
    check(
        "sampling = 0.2",
        "sampling = \"fast\"",
        "sampling = \"fast\"",
        "scenario.sampling",
        "invalid type",
    );
    check(
        "[scenario]",
        "[scenario]\nintervals = 0",
        "intervals = 0",
        "scenario.intervals",
        "at least 1",
    );
    check("ku = 0.1", "ku = 0.1\nkq = 1.0", "kq = 1.0", "kq", "unknown field");
    check("ku = 0.1", "ku = \"high\"", "ku = \"high\"", "controller.weights.ku", "invalid type");
    check("selection = \"paper-2d\"", "lowest = 0", "lowest = 0", "modes.lowest", "at least 1");
    // the first sample's settings and the corrected line search
    let keys = "substeps = 16\nreal_time_iteration = false\nfirst_sample_iterations = 30\n\
                first_sample_guess = \"decay\"\nsecond_order_correction = true\n\
                first_sample_continuation = 4\nfirst_sample_levenberg_marquardt = 1e-2\n\
                rollout_intervals = 3";
    let text = base.replacen("substeps = 16", keys, 1);
    let c = load_str(Path::new("ok.toml"), &text).unwrap_or_else(|e| panic!("{e}"));
    let c = c.control.expect("[scenario]").controller;
    assert_eq!(c.first_sample_iterations, Some(30));
    assert_eq!(c.first_sample_guess, mpc::InitialGuess::Decay);
    assert_eq!(c.globalisation, ocp_transcription::Globalisation::merit_soc());
    assert_eq!(c.first_sample_continuation, 4);
    assert_eq!(c.first_sample_levenberg_marquardt, Some(1e-2));
    assert_eq!(c.rollout_intervals, 3);
    // the horizon's tail: both keys or neither, and the library's checks at their keys
    let text = base.replacen(
        "substeps = 16",
        "substeps = 16\ntail_from_interval = 12\ntail_substeps = 2",
        1,
    );
    let c = load_str(Path::new("ok.toml"), &text).unwrap_or_else(|e| panic!("{e}"));
    let c = c.control.expect("[scenario]").controller;
    let tail = ocp_transcription::TailSubsteps { from_interval: 12, substeps: 2 };
    assert_eq!(c.integrator.tail, Some(tail));
    check(
        "substeps = 16",
        "substeps = 16\ntail_substeps = 2",
        "tail_substeps = 2",
        "controller.tail_substeps",
        "needs `tail_from_interval` too",
    );
    check(
        "substeps = 16",
        "substeps = 16\ntail_from_interval = 0\ntail_substeps = 2",
        "tail_from_interval = 0",
        "controller.tail_from_interval",
        "at least 1",
    );
    check(
        "substeps = 16",
        "rollout_intervals = -1",
        "rollout_intervals = -1",
        "controller.rollout_intervals",
        "",
    );
    check(
        "substeps = 16",
        "substeps = 16\nreal_time_iteration = false\nfirst_sample_continuation = 2",
        "first_sample_continuation = 2",
        "controller.first_sample_continuation",
        "needs first_sample_iterations",
    );
    check(
        "substeps = 16",
        "substeps = 16\nreal_time_iteration = false\nfirst_sample_iterations = 5\n\
         first_sample_levenberg_marquardt = -1.0",
        "first_sample_levenberg_marquardt = -1.0",
        "controller.first_sample_levenberg_marquardt",
        "≥ 0",
    );
    check(
        "substeps = 16",
        "substeps = 16\nreal_time_iteration = false\nfirst_sample_iterations = 0",
        "first_sample_iterations = 0",
        "controller.first_sample_iterations",
        "at least 1",
    );
    check(
        "substeps = 16",
        "substeps = 16\nline_search = false\nsecond_order_correction = true",
        "second_order_correction = true",
        "controller.second_order_correction",
        "line_search = true",
    );
    check(
        "substeps = 16",
        "substeps = 16\nfirst_sample_guess = \"zero\"",
        "first_sample_guess = \"zero\"",
        "first_sample_guess",
        "linear-mpc",
    );
}

/// Every shipped scene builds and takes a few steps (the full runs are in CI via the CLI).
#[test]
fn shipped_scenes_load_and_step() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let s = load(&path).unwrap_or_else(|e| panic!("{e}"));
        if let Some(c) = &s.control {
            c.scenario.validate().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
        let mut plant = s.plant().unwrap_or_else(|e| panic!("{e}"));
        for _ in 0..3 {
            plant.step().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
        n += 1;
    }
    assert!(n >= 5, "found {n} scenes");
}

/// The shipped MPC scenes build the same closed loops as the mpc crate's presets
/// (`Scenario::paper_2d(50)`, `paper_3d(50)`): structure size, inputs (up to their names),
/// mode set, disturbance axis, root, timing and weights.
#[test]
fn shipped_mpc_scenes_match_the_mpc_presets() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    for (file, preset) in [
        ("paper-2d-mpc.toml", mpc::Scenario::paper_2d(50).unwrap()),
        ("paper-3d-mpc.toml", mpc::Scenario::paper_3d(50).unwrap()),
        ("paper-3d-mpc-full-range.toml", mpc::Scenario::paper_3d(50).unwrap()),
        ("paper-3d-mpc-paper-model.toml", mpc::Scenario::paper_3d(50).unwrap()),
        ("paper-3d-mpc-ku1.toml", {
            let mut p = mpc::Scenario::paper_3d(50).unwrap();
            p.mpc.cost.ku = mpc::SPATIAL_INPUT_WEIGHT;
            p
        }),
    ] {
        let s = load(&dir.join(file)).unwrap_or_else(|e| panic!("{e}"));
        let c = s.control.expect("[scenario]");
        let sc = &c.scenario;
        assert_eq!(sc.structure.dim(), preset.structure.dim(), "{file}");
        assert_eq!(sc.structure.joints().len(), preset.structure.joints().len());
        let strip = |i: &mpc::ControlInput| match i {
            mpc::ControlInput::JointTorque { joint, axis, .. } => format!("T {joint} {axis:?}"),
            mpc::ControlInput::Follower { beam, node, load, .. } => {
                format!("F {beam} {node} {load:?}")
            }
        };
        let a: Vec<String> = sc.inputs.iter().map(strip).collect();
        let b: Vec<String> = preset.inputs.iter().map(strip).collect();
        assert_eq!(a, b, "{file}");
        assert_eq!(format!("{:?}", sc.selection), format!("{:?}", preset.selection));
        assert_eq!(sc.omega_direction, preset.omega_direction);
        assert_eq!((sc.root.as_str(), sc.center), (preset.root.as_str(), preset.center));
        assert_eq!(
            (sc.duration, sc.output_interval, sc.snapshot_interval, sc.rom_plant_substeps),
            (preset.duration, preset.output_interval, preset.snapshot_interval, 16)
        );
        assert_eq!(sc.plant.dt, preset.plant.dt);
        if file == "paper-3d-mpc-full-range.toml" {
            // a 5 s horizon of 20 intervals (docs/mpc.md, "Toward ω0 = 1.5"), the rest the paper's
            let timing = mpc::Timing { horizon: 5.0, intervals: 20, ..preset.mpc.timing };
            assert_eq!(sc.mpc, mpc::MpcSettings { timing, ..preset.mpc.clone() });
        } else {
            assert_eq!(sc.mpc, preset.mpc);
        }
        // the paper-model 3D scene defaults to the largest ω0 its model stabilises
        let omega0 = if file == "paper-3d-mpc-paper-model.toml" { 0.75 } else { 1.0 };
        assert_eq!((c.plant, c.omega0), (mpc::PlantKind::Fe, omega0));
        if file == "paper-3d-mpc-ku1.toml" {
            assert_eq!(c.controller, mpc::ControllerSettings::real_time_spatial());
        }
        if file == "paper-3d-mpc.toml" {
            // the real-time preset with the shooting intervals on the thread pool
            let parallel = mpc::ControllerSettings {
                parallel_intervals: true,
                ..mpc::ControllerSettings::exact_joints()
            };
            assert_eq!(c.controller, parallel);
        }
        if file == "paper-3d-mpc-full-range.toml" {
            // the full SQP (≤ 20 iterations) with the LM term on 24 elastic modes per link, × 8,
            // 40 first-sample iterations, two intervals re-simulated per later sample
            // (docs/mpc.md, "The later samples' warm start", "Unit rotations")
            let full = mpc::ControllerSettings {
                real_time_iteration: false,
                max_iterations: 20,
                first_sample_iterations: Some(40),
                link_elastic_modes: Some(24),
                integrator: ocp_transcription::IntegratorSettings::new(
                    ocp_transcription::IntegratorKind::ImplicitMidpoint,
                    8,
                ),
                ..mpc::ControllerSettings::exact_joints()
            };
            assert_eq!(c.controller, full);
        }
        if file == "paper-3d-mpc-paper-model.toml" {
            assert_eq!(c.controller.model, mpc::ModelKind::Paper);
        }
    }
}

/// The built-in default scene is the shipped paper 2D NMPC scene, with paper defaults and
/// the real-time controller.
#[test]
fn default_scene_is_the_shipped_paper_2d_mpc() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(crate::DEFAULT_SCENE_PATH);
    assert_eq!(std::fs::read_to_string(&path).unwrap(), crate::DEFAULT_SCENE);
    let s = load_str(Path::new(crate::DEFAULT_SCENE_PATH), crate::DEFAULT_SCENE).unwrap();
    let c = s.control.expect("the default scene has a [scenario]");
    assert_eq!(c.scenario.mpc, mpc::MpcSettings::default());
    // the shipped scene runs the real-time configuration (docs/mpc.md, "Real time")
    assert_eq!(c.controller, mpc::ControllerSettings::real_time(false));
    assert_eq!(c.scenario.inputs.len(), 3);
    assert_eq!(s.name, "paper-2d-mpc");
}

/// `[[reference.joints]]`: the shipped fold scene loads with its two commands; each rule's
/// error names its field, and the paper model refuses commands.
#[test]
fn joint_commands_load_and_name_their_fields() {
    let text = include_str!("../../../../scenes/fold-2d.toml");
    let s = load_str(Path::new("fold-2d.toml"), text).unwrap();
    let c = s.control.unwrap();
    assert_eq!(c.scenario.references.len(), 2);
    assert_eq!(c.scenario.references[0].joint, "elbow");
    assert_eq!(c.scenario.references[1].ramp_s, 4.0);
    assert_eq!(c.scenario.references[1].start_s, 0.0);
    let late = text.replacen("ramp_s = 4.0 }", "ramp_s = 2.0, start_s = 1.5 }", 1);
    let r = &load_str(Path::new("fold-2d.toml"), &late).unwrap().control.unwrap().scenario;
    assert_eq!((r.references[0].ramp_s, r.references[0].start_s), (2.0, 1.5));
    for (from, to, field) in [
        ("angle_deg = 90.0", "angle_deg = 270.0", "reference.joints[0].angle_deg"),
        (
            "axis = [0.0, 1.0, 0.0], angle_deg = 90.0",
            "axis = [0.0, 0.0, 0.0], angle_deg = 90.0",
            "reference.joints[0].axis",
        ),
        (
            "ramp_s = 4.0 },\n  { joint = \"root\"",
            "ramp_s = -1.0 },\n  { joint = \"root\"",
            "reference.joints[0].ramp_s",
        ),
        (
            "ramp_s = 4.0 },\n  { joint = \"root\"",
            "ramp_s = 4.0, start_s = -2.0 },\n  { joint = \"root\"",
            "reference.joints[0].start_s",
        ),
        ("joint = \"root\", axis", "joint = \"wrist\", axis", "reference.joints[1].joint"),
        ("joint = \"root\", axis", "joint = \"elbow\", axis", "reference.joints[1].joint"),
        ("model = \"exact-joints\"", "model = \"paper\"", "reference"),
    ] {
        assert!(text.contains(from), "{from}");
        let bad = text.replacen(from, to, 1);
        let msg = match load_str(Path::new("fold-2d.toml"), &bad) {
            Ok(_) => panic!("`{to}` was accepted"),
            Err(e) => e.to_string(),
        };
        assert!(msg.contains(field), "expected `{field}` in: {msg}");
    }
}
