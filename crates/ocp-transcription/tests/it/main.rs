//! Integration tests of `ocp-transcription` (one binary).

mod adaptive;
mod explore;
mod globalisation;
mod integrators;
mod sqp;
