//! Integration tests of `ocp-transcription` (one binary).

mod adaptive;
mod globalisation;
mod integrators;
mod sqp;
