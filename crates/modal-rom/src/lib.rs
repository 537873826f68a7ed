//! Constrained linear modes and the nonlinear modal reduced-order model of intrinsic beam
//! structures with joints (paper §3, eqs. 13–32; theory.md §4–§7).
//!
//! **Constrained modes (30)–(32).** At rest, the staggered FE model of a structure is
//! `B Ẋ = A X`, `G X = 0`. With node velocities `X1`, element forces `X2`, the skew operator's
//! node/element block `D` and the velocity rows `G1` of supports and joints, the modes solve
//!
//! ```text
//!   ω² B1 φ1 = D B2⁻¹ Dᵀ φ1,   φ1 ∈ null(G1) (+ rigid C rows, massless M rows),
//!   φ2 = +B2⁻¹ Dᵀ φ1 / ω,      ⟨φ1i, B1 φ1j⟩ = δij,   ⟨φ1i, D φ2j⟩ = ω_j δij,
//! ```
//!
//! ([`solve_second_order`], [`ModalBasis`]): rigid modes first (exact rotations about the root, then
//! joint by joint), then elastic modes by frequency, labelled from their energy split.
//!
//! **Modal model (14)–(21).** `x1 = φ1j q1j`, `x2 = φ2j q2j`:
//!
//! ```text
//!   q̇ = W q + N(q) q + [η; 0],   W = [[Σ, Ω], [−Ω, 0]],
//!   N(q) = [[−q1l Γ1^l, −q2l Γ2^l], [q2l (Γ2^l)ᵀ, 0]],
//!   Γ1^l_ij = ⟨φ1i, L1(φ1j) M φ1l⟩,  Γ2^l_ij = ⟨φ1i, L2(φ2j) C φ2l⟩,  η = B_u u,
//! ```
//!
//! with `ε = ½ qᵀq` conserved without damping and input (`qᵀN(q)q = 0`).
//!
//! **Quaternion modes (22)–(29).** `ξ = φξj qξj`, `φξ0 = ξ̄`, `φξj = Uω(ξ̄) φωj`,
//! `Aξ q̇ξ = qξl Γξ^l q1`, `Aξ = ⟨φξi, φξj⟩`, `Γξ^l_ij = ⟨φξi, U(φωj) φξl⟩`; zero or dependent
//! quaternion modes are dropped so `Aξ` is invertible ([`ModalRom`]).
//!
//! Also: projection of FE states and reconstruction of fields and positions
//! ([`Fields`]), export to JSON + `.npy` and a reader ([`Metadata`]), a mode report for
//! the CLI ([`mode_report`]) and the paper's canonical models ([`samples`]).
//!
//! # Example
//!
//! The paper's 2D two-link (8 elements per link), its constrained modes and the reduced model
//! on the paper's mode set (2 rigid + 4 axial + 4 bending), undamped:
//!
//! ```
//! use modal_rom::{samples, RomOptions};
//!
//! let sample =
//!     samples::paper_2d(8, 0.0, false, &samples::paper_2d_selection(), &RomOptions::default())?;
//! let rom = &sample.rom;
//! assert_eq!(rom.n_rigid(), 2);
//! // The nonlinear terms do no work: qᵀN(q)q = 0 for any state (eq. 21), to round-off.
//! let q: Vec<f64> = (0..rom.n_state()).map(|i| 0.1 * (i as f64 + 1.0).sin()).collect();
//! assert!(rom.energy_neutrality(&q)?.abs() < 1e-12);
//! let mut qdot = vec![0.0; rom.n_state()];
//! rom.rhs(&q, &vec![0.0; rom.n_inputs()], &mut qdot)?;
//! # Ok::<(), modal_rom::ModalError>(())
//! ```

mod basis;
mod blocks;
mod eigen;
mod error;
pub mod exact_joints;
mod export;
mod lanczos;
mod layout;
mod midpoint;
pub mod npy;
mod projection;
mod report;
mod rigid;
mod rom;
pub mod samples;
mod sparse_modes;
mod sparse_problem;
mod structure;
mod tensor;

pub use basis::{BasisSettings, KindCounts, ModalBasis, ModeKind, ModeSelection};
pub use blocks::BlockDiag;
pub use eigen::{solve as solve_second_order, EigenSettings, RawModes, SecondOrderProblem};
pub use error::{ModalError, Result};
pub use exact_joints::{ExactJointsRom, LinkBasis, LinkBasisSettings};
pub use export::{ArrayInfo, Metadata, FORMAT, VERSION};
pub use layout::{BeamLayout, Components, FullIndex, Layout};
pub use projection::Fields;
pub use report::{mode_report, report_of, BeamShape, ModeReport, ModeShape};
pub use rigid::{chain_rotations, rigid_rotation_fields, RigidRotation};
pub use rom::{Input, ModalRom, QuaternionModel, RomOptions};
pub use sparse_modes::{solve_sparse, sparse_mode_report, SparseModes, SparseSettings};
pub use sparse_problem::SparseProblem;
pub use structure::StructureModel;
pub use tensor::SparseTensor3;

#[cfg(test)]
mod basis_tests;
#[cfg(test)]
mod rom_tests;
#[cfg(test)]
pub(crate) mod testing;
