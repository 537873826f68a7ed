//! Integration tests of `ocp-transcription` (one binary).

mod adaptive;
mod globalisation;
mod hessian;
mod integrators;
mod reference;
mod sqp;
