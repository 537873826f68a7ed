//! Structures of intrinsic beams tied by joints and supports (paper eqs. 11–12).
pub mod error;
pub mod joint;
pub mod nullspace;
pub mod plant;
pub mod samples;
pub mod structure;
pub mod studies;
pub use error::{MultibodyError, Result};
pub use plant::{Plant, PlantSettings, StepReport};
