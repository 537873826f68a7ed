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
//!
//! # From a structure to a reduced model: [`StructureModel`], [`ModalBasis`], [`ModalRom`]
//!
//! The operators of a structure ([`StructureModel::new`]), its constrained modes
//! ([`StructureModel::modes`]), a selection ([`ModalBasis::select`]) and the reduced model on
//! it ([`ModalRom::new`]); a rigid rotation of the structure lies in the span of the rigid
//! modes, so projecting it ([`ModalRom::project_full`]) and rebuilding the fields
//! ([`ModalRom::reconstruct_full`]) gives it back:
//!
//! ```
//! use intrinsic_beam::Section;
//! use modal_rom::{BasisSettings, ModalRom, ModeSelection, RomOptions, StructureModel};
//! use nalgebra::Vector3;
//!
//! let structure = multibody_constraints::samples::paper_2d(Section::paper_2d(), 6, 0.0)?;
//! let model = StructureModel::new(&structure)?;
//! let basis = model.modes(&BasisSettings::default())?;
//! assert_eq!(basis.n_rigid(), 2); // root hinge and elbow hinge
//! let (b1, b2, d) = basis.orthonormality_residuals();
//! assert!(b1 < 1e-10 && b2 < 1e-10 && d < 1e-8, "{b1} {b2} {d}");
//! let picked = basis.select(&ModeSelection::Lowest(6))?;
//! let rom = ModalRom::new(&picked, Some(&model.damping), &[], &RomOptions::default())?;
//! assert_eq!(rom.n_modes(), 6);
//!
//! let x = structure.rigid_rotation_state(Vector3::new(0.0, 0.5, 0.0), Vector3::zeros());
//! let q = rom.project_full(&x, None)?;
//! let back = rom.reconstruct_full(&q)?;
//! let err = x.iter().zip(&back).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
//! assert!(err < 1e-10, "{err}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Mode tables: [`mode_report`]
//!
//! The first modes of a structure with frequencies and labels, as `flexmpc modes` prints them:
//!
//! ```
//! use intrinsic_beam::Section;
//! use modal_rom::{mode_report, BasisSettings};
//!
//! let structure = multibody_constraints::samples::paper_2d(Section::paper_2d(), 6, 0.0)?;
//! let r = mode_report(&structure, 5, &BasisSettings::default())?;
//! assert_eq!(r.labels[..2], ["rigid", "rigid"]);
//! assert!(r.frequencies_rad_s.windows(2).all(|w| w[0] <= w[1]));
//! assert!(mode_report(&structure, 0, &BasisSettings::default()).is_err());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # The eigen solver: [`solve_second_order`]
//!
//! The constrained second-order problem (30)–(32) solved directly, here on a structure's own
//! blocks ([`StructureModel::problem`]); its frequencies are the basis's:
//!
//! ```
//! use intrinsic_beam::Section;
//! use modal_rom::{solve_second_order, BasisSettings, EigenSettings, StructureModel};
//!
//! let structure = multibody_constraints::samples::paper_2d(Section::paper_2d(), 4, 0.0)?;
//! let model = StructureModel::new(&structure)?;
//! let raw = solve_second_order(&model.problem, &EigenSettings::default(), None)?;
//! let basis = model.modes(&BasisSettings::default())?;
//! assert_eq!(raw.n_rigid, 2);
//! let last = raw.omega.len() - 1;
//! assert!((raw.omega[last] - basis.omega()[last]).abs() <= 1e-9 * raw.omega[last]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Export: [`ModalRom::export`], [`ModalRom::read`], [`npy`]
//!
//! A model written as JSON metadata plus `.npy` arrays (for NumPy and other tools) reads
//! back to the same model:
//!
//! ```
//! use modal_rom::{samples, ModalRom, RomOptions};
//!
//! let s = samples::paper_2d(4, 0.0, true, &samples::paper_2d_selection(), &RomOptions::default())?;
//! let dir = std::env::temp_dir().join(format!("modal-rom-doc-{}", std::process::id()));
//! let meta = s.rom.export(&dir)?;
//! let back = ModalRom::read(&dir)?;
//! assert_eq!((back.n_state(), back.n_inputs()), (s.rom.n_state(), s.rom.n_inputs()));
//! assert_eq!(meta.n_state, s.rom.n_state());
//! let sigma = modal_rom::npy::read(&dir.join("sigma.npy"))?;
//! assert_eq!(sigma.shape, [s.rom.n_modes(), s.rom.n_modes()]);
//! std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # The exact-joints model: [`ExactJointsRom`], [`exact_joints::paper_reduction`]
//!
//! On the paper's constrained modes as link fields, the exact-joints model (theory.md §10)
//! starts where the paper's model does and conserves its energy `½|p|² + ½|p2|²` without
//! damping and inputs (the right-hand side does no work):
//!
//! ```
//! use modal_rom::{exact_joints, samples, RomOptions};
//!
//! let s = samples::paper_2d(4, 0.0, false, &samples::paper_2d_selection(), &RomOptions::default())?;
//! let picked = s.basis.select(&samples::paper_2d_selection())?;
//! let rom = exact_joints::paper_reduction(&s.structure, &s.model, &picked, None, &[])?;
//! let mut x = rom.reference_state();
//! for (i, v) in x[..rom.n_p()].iter_mut().enumerate() {
//!     *v = 0.1 * (i as f64 + 1.0).cos();
//! }
//! let mut f = vec![0.0; rom.n_state()];
//! rom.rhs(&x, &[], &mut f)?;
//! assert!(rom.energy(&x) > 0.0);
//! // dε/dt = p·ṗ + p2·ṗ2 = 0
//! let n = rom.n_p() + rom.n_p2();
//! let work: f64 = x[..n].iter().zip(&f[..n]).map(|(a, b)| a * b).sum();
//! assert!(f[..n].iter().any(|v| v.abs() > 1e-3), "the state moves");
//! assert!(work.abs() < 1e-12, "{work}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
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
pub use export::{
    read_exact_joints, ArrayInfo, ExactJointsMetadata, ExportedJoint, Metadata,
    EXACT_JOINTS_FORMAT, EXACT_JOINTS_VERSION, FORMAT, VERSION,
};
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
