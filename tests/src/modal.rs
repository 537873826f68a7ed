//! Verification cases of the `modal-rom` crate (names `modal-rom/<case>`).

use crate::Case;

/// The cases of `modal-rom`.
pub fn cases() -> Vec<Case> {
    Vec::new()
}
