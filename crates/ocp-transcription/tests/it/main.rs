//! Integration tests of `ocp-transcription` (one binary).

mod adaptive;
mod evaluations;
mod globalisation;
mod hessian;
mod integrators;
mod quasi_newton;
mod reference;
mod simplified_newton;
mod sqp;
mod tail;
mod warm_start;
