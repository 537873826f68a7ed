//! Tests of the verification crate: the studies on cheap settings, the dense modes oracle
//! against modal-rom, and the CI-sized scene fuzz (one test binary).

mod beam_studies;
mod dense_modes;
mod fuzz_scene;
mod multibody_studies;
