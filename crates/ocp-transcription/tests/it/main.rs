//! Integration tests of `ocp-transcription` (one binary).

mod adaptive;
mod integrators;
mod sqp;
