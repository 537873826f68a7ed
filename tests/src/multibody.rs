//! Verification cases of the `multibody-constraints` crate (names `multibody-constraints/<case>`).

use crate::Case;

/// The cases of `multibody-constraints`.
pub fn cases() -> Vec<Case> {
    Vec::new()
}
