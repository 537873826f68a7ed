//! Constrained linear modes and the nonlinear modal model (paper eqs. 13–32).
pub mod basis;
pub mod eigen;
pub mod error;
pub mod layout;
pub use error::{ModalError, Result};
#[cfg(test)]
mod basis_tests;
pub mod projection;
pub mod rigid;
pub mod rom;
#[cfg(test)]
mod rom_tests;
pub mod samples;
pub mod structure;
pub mod tensor;
#[cfg(test)]
pub(crate) mod testing;
