//! Closed-loop NMPC and linear MPC of flexible multibody structures (paper §4–5).
//!
//! This crate will join the modal model (controller) and the FE plant (issue 6): adapters from
//! the ROM to the `Dynamics` trait, controllers, closed loops, the paper's 2D and 3D
//! scenarios and sweeps. It is empty until then.
