//! Geometrically exact beams in the intrinsic formulation (paper eqs. 1–10).
//!
//! This crate will hold sections, the staggered energy-preserving finite-element operators,
//! loads, time integrators and kinematics (being built under issue 2).

pub mod operators;
