//! Verification cases of the `intrinsic-beam` crate (names `intrinsic-beam/<case>`).

use crate::Case;

/// The cases of `intrinsic-beam`.
pub fn cases() -> Vec<Case> {
    Vec::new()
}
