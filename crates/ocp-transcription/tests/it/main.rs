//! Integration tests of `ocp-transcription` (one binary).

mod integrators;
mod sqp;
