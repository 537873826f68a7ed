//! Constrained linear modes and the nonlinear modal model (paper eqs. 13–32).
//!
//! This crate will hold the `ModalBasis` (eqs. 30–32), the modal tensors `W`, `Γ1`, `Γ2`
//! (eqs. 14–21), quaternion modes and the augmented model (eqs. 22–29), and the projection
//! of FE states onto modes (issue 4). It is empty until then.
