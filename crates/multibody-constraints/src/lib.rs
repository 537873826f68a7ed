//! Structures of intrinsic beams tied by joints and supports (paper eqs. 11–12).
//!
//! This crate will hold the `Structure` (beams, joints, supports), the linearised constraint
//! rows `G` with a null-space basis `Z`, and the constrained implicit-midpoint FE plant
//! (issue 3). It is empty until then.
