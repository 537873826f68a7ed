//! The controller a scene gets without solver settings is the library's default, the
//! real-time NMPC; the full SQP is two keys away (`real_time_iteration = false`,
//! `retry = true`), and `retry = true` alone turns the relaxed retry on with its α = 0.5.

use std::path::Path;

use mpc::ControllerSettings;

/// `scenes/paper-2d-mpc.toml` with its `[controller]` table replaced by `controller`.
fn paper_2d_with(controller: &str) -> flexmpc::scene::Scene {
    let text = flexmpc::DEFAULT_SCENE;
    let start = text.find("\n[controller]\n").expect("the scene has [controller]");
    let end = start + 1 + text[start + 1..].find("\n[").expect("a table after [controller]");
    let text = format!("{}\n{controller}\n{}", &text[..start], &text[end..]);
    flexmpc::scene::load_str(Path::new("defaults.toml"), &text).unwrap()
}

#[test]
fn a_scene_without_solver_settings_gets_the_real_time_nmpc() {
    let d = ControllerSettings::default();
    assert_eq!(d, ControllerSettings::real_time(true));
    assert!(d.real_time_iteration && d.retry_relaxation.is_none());
    assert!(d.validate().is_ok());
    let c = paper_2d_with("").control.unwrap();
    assert_eq!(c.controller, d);
    let c = paper_2d_with("[controller]\nkind = \"nmpc\"").control.unwrap();
    assert_eq!(c.controller, d);
}

#[test]
fn the_full_sqp_is_two_keys_away() {
    let full = ControllerSettings::full_sqp();
    assert!(!full.real_time_iteration);
    assert_eq!(full.retry_relaxation, Some(0.5));
    assert!(full.validate().is_ok());
    let c = paper_2d_with("[controller]\nreal_time_iteration = false\nretry = true");
    assert_eq!(c.control.unwrap().controller, full);
    let c = paper_2d_with("[controller]\nretry = true").control.unwrap();
    assert_eq!(c.controller.retry_relaxation, Some(0.5));
    assert!(c.controller.real_time_iteration);
    let c = paper_2d_with("[controller]\nretry_relaxation = 0.25").control.unwrap();
    assert_eq!(c.controller.retry_relaxation, Some(0.25));
}
