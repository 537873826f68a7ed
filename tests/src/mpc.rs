//! Verification cases of the `mpc` crate (names `mpc/<case>`).

use crate::Case;

/// The cases of `mpc`.
pub fn cases() -> Vec<Case> {
    Vec::new()
}
