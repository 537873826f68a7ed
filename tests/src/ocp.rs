//! Verification cases of the `ocp-transcription` crate (names `ocp-transcription/<case>`).

use crate::Case;

/// The cases of `ocp-transcription`.
pub fn cases() -> Vec<Case> {
    Vec::new()
}
