//! `flexmpc` as a library: the scene-file format and the runs behind the `flexmpc` command.
//!
//! The binary (`src/main.rs`) is a thin clap front end over these modules, so that tests,
//! fuzzers and other tools can parse scenes and run them without a subprocess:
//!
//! - [`scene`]: TOML scene files → a ready constrained FE plant; every error names the file,
//!   line and field ([`scene::SceneError`]).
//! - [`run`]: time simulation of a scene with CSV output.
//! - [`modes`]: constrained linear modes of a scene's structure, with tables and plots.
//! - [`plot`]: SVG time-series plots (plotters).
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
//! assert_eq!(scene.plant.structure().beams().len(), 1);
//! ```

pub mod modes;
pub mod plot;
pub mod run;
pub mod scene;

/// The default scene, built in so that `cargo run --release` works from any directory.
pub const DEFAULT_SCENE: &str = include_str!("../../../scenes/cantilever.toml");
