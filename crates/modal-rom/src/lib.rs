//! Constrained linear modes and the nonlinear modal model (paper eqs. 13–32).
pub mod basis;
pub mod eigen;
pub mod error;
pub mod layout;
pub use error::{ModalError, Result};
#[cfg(test)]
mod basis_tests;
pub mod rigid;
#[cfg(test)]
pub(crate) mod testing;
