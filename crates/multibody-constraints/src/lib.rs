//! Structures of intrinsic beams tied by joints and supports (paper §2.3, eqs. 11–12), the
//! linearised constraint rows `G` with a null-space basis `Z` (eq. 32), and the constrained
//! implicit-midpoint FE plant.
//!
//! # Governing equations
//! Each beam obeys eqs. (1)–(2), discretised by `intrinsic-beam` (staggered grid, end values
//! `x2_L`, `x2_R`). A joint ties ends `j` with rotations `T_j = T(ξ_j)` (eq. 9) and signs
//! `σ_j = +1` at `s = 0`, `−1` at `s = L`:
//!
//! ```text
//! T^a v^a(L) = T^b v^b(0) = T^c v^c(0)                       (11)  velocity compatibility
//! −T^a f^a(L) + T^b f^b(0) + T^c f^c(0) = 0                   (12)  force balance
//! ```
//!
//! applied per direction: along a *rigid* axis `d`, `d·T_j x1_j` is common to all ends and
//! `Σ σ_j d·T_j x2_j = 0`; along a *free* axis each end's `d·T_j x2_j = 0` (or an applied joint
//! torque). Rotations alike with `ω`, `m` ("rigid joint": (11)–(12) on `ω`, `m` as well). Axes
//! may be global, carried by one end, or each end's own (the paper's §5.3 wheel joint:
//! `ω1^a = ω1^b`, `m1^a = m1^b`, bending moments zero). With orthonormal axes per end,
//! `Σ_j σ_j x1_jᵀ x2_j = 0` whenever the rows hold: joints do no work, and the discrete energy
//! `ε_h = ½ Σ w_n x1ᵀ M x1 + ½ Σ h_e x2ᵀ C x2` (eq. 6) changes only by load power.
//!
//! # Time stepping (theory.md §3)
//! Implicit midpoint on the DAE: beam rows at the midpoint, joint rows at the midpoint with one
//! rotation per end, `T_j = T(exp(dt/2 U(ω_mid)) ξ_j)` (eqs. 7–8), the same rotation used for
//! dead loads and for `r⁺ = r + dt T_mid v_mid` (eq. 10). Hence the joint power cancels exactly
//! (energy conserved to solver tolerance), joined ends move by identical increments (no gap
//! drift), and `T` follows each end's quaternion so joint angles evolve. Newton with faer's
//! sparse LU on a fixed pattern; the factorisation is reused while it contracts.
//!
//! # Modules and API
//! * [`JointKind`] (weld, ball, hinge, universal, custom per-direction), [`Joint`],
//!   [`Support`]: the rows (11)–(12).
//! * [`Structure`]: beams placed in space (explicitly or by joint
//!   angles), topology validation, layout, [`Structure::constraint_matrix`] (`G`),
//!   [`Structure::linear_operators`] (`B`, `A`), rigid-rotation states.
//! * [`null_space`]: orthonormal `Z` with `G Z = 0` (faer SVD), redundant rows named.
//! * [`Plant`]: steps, inputs (point loads follower/dead, gravity, joint torques,
//!   changeable every step), outputs (joint angles, reactions, positions, energy).
//! * [`samples`] — the paper's two-links, Fig. 2's ball joint, an L-frame, the rigid double
//!   pendulum.
//!
//! ```
//! use intrinsic_beam::Section;
//! use multibody_constraints::{samples, Plant, PlantSettings};
//! use nalgebra::Vector3;
//!
//! let structure = samples::paper_2d(Section::paper_2d(), 8, 0.0).unwrap();
//! let omega = structure.rigid_rotation_state(Vector3::new(0.0, 1.0, 0.0), Vector3::zeros());
//! let mut plant = Plant::new(structure, PlantSettings::default()).unwrap();
//! plant.set_state(&omega).unwrap();
//! plant.set_joint_torque("root", None, 0.1).unwrap();
//! for _ in 0..10 {
//!     plant.step().unwrap();
//! }
//! assert!(plant.joint_angles()[1] > 0.0); // the root support turns about e2
//! ```

mod error;
mod joint;
mod nullspace;
mod plant;
pub mod samples;
mod structure;

pub use error::{MultibodyError, Owner, Result};
pub use joint::{
    rows, Axis, End, EndRef, Frame, Freedom, Joint, JointKind, Part, Row, RowKind, Support,
};
pub use nullspace::{null_space, RANK_TOLERANCE};
pub use plant::{JointBalance, Plant, PlantSettings, StepReport};
pub use structure::{
    ConstraintMatrix, JointInfo, Placement, RowLabel, Structure, StructureBeam, StructureSettings,
};
