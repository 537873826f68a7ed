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
//!
//! # Checking a scene: [`scene::check_str`], [`scene::check`]
//!
//! `check` builds what every command builds; a wrong value is refused with the file, the
//! line and the field:
//!
//! ```
//! use std::path::Path;
//! let text = flexmpc::DEFAULT_SCENE.replacen("elements = 50", "elements = -3", 1);
//! let Err(e) = flexmpc::scene::check_str(Path::new("bad.toml"), &text) else {
//!     panic!("a negative element count is refused")
//! };
//! let e = e.to_string();
//! assert!(e.contains("bad.toml") && e.contains("elements"), "{e}");
//! let ok = flexmpc::scene::check_str(Path::new("ok.toml"), flexmpc::DEFAULT_SCENE).unwrap();
//! assert!(ok.scene.control.is_some());
//! ```
//!
//! # Simulating: [`run::simulate`]
//!
//! The uncontrolled FE plant of a scene (its control inputs at zero), written as
//! `timeseries.csv`, one row per output step:
//!
//! ```
//! use std::path::Path;
//! let text = flexmpc::DEFAULT_SCENE.replace("elements = 50", "elements = 4")
//!     .replace("duration = 7.5\noutput_every", "duration = 0.05\noutput_every");
//! let scene = flexmpc::scene::load_str(Path::new("two-link.toml"), &text)?;
//! let out = std::env::temp_dir().join(format!("flexmpc-doc-sim-{}", std::process::id()));
//! let r = flexmpc::run::simulate(scene, &out, true)?;
//! assert_eq!(r.steps, 50);
//! let rows = std::fs::read_to_string(&r.csv)?.lines().count();
//! assert_eq!(rows, 1 + 1 + 50 / 10); // header, t = 0, every 10 steps
//! std::fs::remove_dir_all(&out)?;
//! # Ok::<(), anyhow::Error>(())
//! ```
//!
//! # Closed loops: [`control::run_mpc`], [`control::run_sweep`], [`vtk`]
//!
//! One closed loop of a scene's `[scenario]` (here the default scene on a coarse mesh, for
//! 0.4 s), with [`control::Overrides`] as on the command line; its output folder holds the
//! CSV, the solver log, the summary and the report. Its snapshots become VTK files for
//! ParaView:
//!
//! ```
//! use std::path::Path;
//! use flexmpc::control::{run_mpc, run_sweep, Overrides, OutputOptions};
//!
//! let text = flexmpc::DEFAULT_SCENE.replace("elements = 50", "elements = 4");
//! let scene = flexmpc::scene::load_str(Path::new("small.toml"), &text)?;
//! let overrides = Overrides {
//!     duration: Some(0.4),
//!     plant: Some(mpc::PlantKind::Rom),
//!     ..Default::default()
//! };
//! let out = std::env::temp_dir().join(format!("flexmpc-doc-mpc-{}", std::process::id()));
//! let quiet = OutputOptions { quiet: true, timings: false };
//! let o = run_mpc(&scene, &overrides, &out, quiet)?;
//! assert_eq!(o.result.samples.len(), 2); // τs = 0.2 s
//! assert!(o.csv.exists() && o.summary.exists() && o.report.exists());
//! let frames = flexmpc::vtk::frames_of_snapshots(&o.result.snapshots, &scene.structure);
//! let pvd = flexmpc::vtk::write(&out.join("vtk"), "mpc", &frames)?;
//! assert!(std::fs::read_to_string(pvd)?.contains("mpc-000000.vtu"));
//!
//! let kinds = [mpc::ControllerKind::Lmpc];
//! let sweep = run_sweep(&scene, &overrides, &[0.5, 1.0], &kinds, &out.join("sweep"), quiet)?;
//! assert_eq!(sweep.runs.len(), 2);
//! assert!(sweep.runs.iter().all(|r| r.result.is_ok()));
//! std::fs::remove_dir_all(&out)?;
//! # Ok::<(), anyhow::Error>(())
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
