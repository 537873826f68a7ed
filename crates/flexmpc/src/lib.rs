//! `flexmpc` as a library: the scene-file format and the runs behind the `flexmpc` command.
//!
//! The binary (`src/main.rs`) is a thin clap front end over these modules, so that tests,
//! fuzzers and other tools can parse scenes and run them without a subprocess:
//!
//! - [`scene`]: TOML scene files → a ready constrained FE plant; every error names the file,
//!   line and field ([`scene::SceneError`]).
//! - [`run`]: time simulation of a scene with CSV output.
//! - [`modes`]: constrained linear modes of a scene's structure, with tables and plots.
//! - [`control`]: closed loops (`flexmpc mpc`), sweeps over ω0 (`flexmpc sweep`) and the
//!   first sample's optimal control problem (`flexmpc ocp`) of a
//!   scene's `[scenario]` with the `mpc` crate, written as CSV/JSON.
//! - [`report`]: the offline HTML report (`index.html` + SVG figures) of a closed loop.
//! - [`figures`]: the figures of closed loops and sweeps (snapshots, cost, inputs).
//! - [`plot`]: generic SVG charts (plotters).
//! - [`results`]: run results as data (`SweepRun`) and their CSV files.
//! - [`progress`]: progress indicators on stderr.
//! - [`vtk`]: the deformed structure over time as VTK files for ParaView (`--vtk`).
//! - [`bug_report`]: what an internal error (a bug) tells the user, the binary's panic hook.
//! - [`timings`]: the measured timings, kept in their own files so that every other output
//!   is a pure function of the inputs (`--no-timings` leaves them out).
//!
//! [`DEFAULT_SCENE`] is the paper's 2D NMPC example (`scenes/paper-2d-mpc.toml`), what
//! `cargo run --release` runs without arguments.
//!
//! ```
//! use std::path::Path;
//! let text = r#"
//! description = "a cantilever"
//! components = "planar"
//! [sections.s]
//! preset = "paper-2d"
//! [[beams]]
//! name = "b"
//! section = "s"
//! length = 1.0
//! elements = 10
//! [[supports]]
//! name = "root"
//! end = "b:start"
//! kind = "weld"
//! [run]
//! dt = 1e-3
//! duration = 0.01
//! "#;
//! let scene = flexmpc::scene::load_str(Path::new("inline.toml"), text).unwrap();
//! assert_eq!(scene.structure.beams().len(), 1);
//! ```

pub mod bug_report;
pub mod control;
pub mod figures;
pub mod modes;
pub mod plot;
pub mod progress;
pub mod report;
pub mod results;
pub mod run;
pub mod scene;
pub mod timings;
pub mod vtk;

/// Path (relative to the repository root) of the default scene, used in messages and for the
/// output folder `out/paper-2d-mpc`.
pub const DEFAULT_SCENE_PATH: &str = "scenes/paper-2d-mpc.toml";

/// The default scene — the paper's 2D NMPC example (§5.2) — built in so that
/// `cargo run --release` works from any directory.
pub const DEFAULT_SCENE: &str = include_str!("../../../scenes/paper-2d-mpc.toml");
