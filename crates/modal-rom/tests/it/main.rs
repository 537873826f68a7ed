//! Integration tests of `modal-rom` (one binary).

mod euler_bernoulli;
mod sparse_modes;
