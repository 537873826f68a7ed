//! Geometrically exact beams in the intrinsic formulation (paper eqs. 1–10): sections,
//! the staggered energy-preserving finite-element discretisation, loads, time integration and
//! kinematics.
//!
//! # Governing equations
//! With `x1 = [v, ω]` (velocities) and `x2 = [f, m]` (sectional forces), local frame:
//!
//! ```text
//! M ∂t x1 − ∂s x2 − E x2 + L1(x1) M x1 + L2(x2) C x2 = D0 x1 + D1 ∂s x1 + D2 ∂ss x1 + f1   (1)
//! C ∂t x2 − ∂s x1 + Eᵀ x1 − L1ᵀ(x1) C x2 = 0                                               (2)
//! ε = ½⟨x1, M x1⟩ + ½⟨x2, C x2⟩                                                            (6)
//! ∂s ξ = U(κ + κ0) ξ,  ∂t ξ = U(ω) ξ;   ∂s r = T(e1 + γ),  ∂t r = T v                       (7), (10)
//! ```
//!
//! `E` (3), `L1`, `L2` (4) are in [`operators`], `U` (8) and `T(ξ)` (9) in [`rotation`]. Space is discretised
//! on a staggered grid (theory.md §2): velocities at nodes, forces at elements, boundary
//! values `x2_L`, `x2_R` at the ends, node weights `w_n`; the discrete energy
//! `ε_h = ½ Σ w_n x1ᵀ M x1 + ½ Σ h_e x2ᵀ C x2` changes only by boundary, load and damping power.
//! The implicit midpoint rule keeps that balance exactly per step.
//!
//! # Modules and API
//! * [`Section`] — `M`, `C` (full 6×6, explicit rigid/massless directions), `κ0`,
//!   `D0, D1, D2`; `validate()`; presets [`Section::paper_2d`], [`Section::paper_3d`].
//! * [`Components`] — `Planar` (`k = 3`) or `Spatial` (`k = 6`).
//! * [`Mesh`] — node coordinates, element lengths `h_e`, node weights `w_n`.
//! * [`Beam`] — the per-beam discretisation a multi-beam assembler calls: local layout
//!   `[x1_0..x1_N, x2_0..x2_{N−1}, x2_L, x2_R]` (`k(2N+3)` unknowns), `k(2N+1)` rows
//!   ([`Beam::step_residual`]), a fixed sparse Jacobian pattern
//!   ([`Beam::jacobian_pattern`], shifted by caller offsets) with values in the same order
//!   ([`Beam::jacobian_values`]), the midpoint convention for algebraic unknowns
//!   ([`Beam::midpoint_weight`]), energy, powers, and the linear operators `B`, `A`,
//!   damping ([`Beam::linear_operators`]) for modes.
//! * [`Loads`] — point/distributed, follower/dead loads with time amplitudes.
//! * [`Kinematics`] — node quaternions/positions, advanced in time or rebuilt from
//!   strains.
//! * [`BeamProblem`] — single-beam problems: [`EndCondition`] (free, applied end load,
//!   clamped, pinned, prescribed motion, mixed); [`ImplicitMidpoint`] (Newton on the
//!   step system with the factorisation reused and refreshed once per step, counters).
//! * the step system's linear solver ([`LinearSolver`]): unknowns interleaved along the beam,
//!   block-tridiagonal with `k×k` blocks, solved by the block LU of
//!   a block-tridiagonal LU (blocks written directly on `k`-vectors); faer's
//!   sparse LU ([`SparseLuSystem`], also the constrained plant's solver) for flux damping or singular blocks.
//! * [`ExplicitRk4`] — explicit RK4 for cross-checks when the problem is an ODE.
//! * [`closed_form`] — closed-form frequencies of uniform beams, the references of the
//!   frequency checks (the constrained modes of beams and structures are modal-rom's).
//! * [`samples`] — canonical problems with provenance and known answers, and seeded random
//!   sections and states ([`samples::random`]) for property checks.
//!
//! A multi-beam assembler places each beam's vector at a column offset and its rows at a row
//! offset, appends its own end/joint rows (on the `x2_L`, `x2_R` and end-node `x1` unknowns,
//! at the step midpoint), and solves `Σ residuals = 0` with Newton; after convergence it
//! advances each beam's [`Kinematics`] with [`Kinematics::advance`].
//!
//! # Example
//!
//! A free–free planar beam (the paper's 2D section, damping removed) set moving keeps its
//! discrete energy (6) through implicit-midpoint steps:
//!
//! ```
//! use intrinsic_beam::{
//!     Beam, BeamProblem, Components, EndCondition, ImplicitMidpoint, Kinematics, Loads, Mesh,
//!     NewtonSettings, Section,
//! };
//!
//! let beam =
//!     Beam::new(Section::paper_2d().undamped(), Mesh::uniform(1.0, 10)?, Components::Planar)?;
//! let kinematics = Kinematics::straight(&beam);
//! let mut state = vec![0.0; beam.dim()];
//! for n in 0..=10 {
//!     state[3 * n + 1] = 0.1 * (n as f64 - 5.0); // v3 at node n (planar: v1, v3, ω2)
//! }
//! let problem = BeamProblem::new(beam, EndCondition::Free, EndCondition::Free, Loads::none())?;
//! let mut sim = ImplicitMidpoint::new(problem, state, kinematics, NewtonSettings::default())?;
//! let e0 = sim.energy();
//! for _ in 0..20 {
//!     sim.step(1e-3)?;
//! }
//! // Conserved up to the Newton tolerance (1e-12 on states of order 0.5).
//! assert!((sim.energy() - e0).abs() <= 1e-9 * e0);
//! # Ok::<(), intrinsic_beam::BeamError>(())
//! ```

mod beam;
mod block_tridiagonal;
pub mod closed_form;
mod components;
mod error;
mod kernels;
mod kinematics;
mod loads;
mod mesh;
mod midpoint;
mod null_space;
pub mod operators;
mod problem;
#[cfg(test)]
mod proptests;
mod rk4;
pub mod rotation;
pub mod samples;
mod section;
mod sparse;
mod step_system;

pub use beam::{Beam, EnergyBalance, LinearOperators, StepInput, StepPower};
pub use components::{Components, OUT_OF_PLANE_INDICES, PLANAR_INDICES, SPATIAL_INDICES};
pub use error::{BeamError, Result};
pub use kinematics::Kinematics;
pub use loads::{Amplitude, DistributedLoad, LoadFrame, Loads, PointLoad};
pub use mesh::Mesh;
pub use midpoint::{Counters, ImplicitMidpoint, NewtonSettings, StepRefresh};
pub use null_space::{null_space, NullSpace};
pub use problem::{BeamProblem, End, EndCondition};
pub use rk4::ExplicitRk4;
pub use section::Section;
pub use sparse::SparseLuSystem;
pub use step_system::LinearSolver;
