//! Tests of the verification crate: the studies on cheap settings and the CI-sized scene fuzz
//! (one test binary).

mod beam_studies;
mod fuzz_scene;
mod multibody_studies;
