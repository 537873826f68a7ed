//! Closed-loop NMPC and linear MPC of flexible multibody structures (paper §4–5).
//!
//! **Controller model.** The augmented modal model (29) on `q_a = [q1, q2, qξ]`
//! ([`RomDynamics`], exact Jacobian and second derivatives, constant linear part `W` for the
//! Lawson integrator):
//!
//! ```text
//!   q̇1 = Σ q1 + Ω q2 − q1_l Γ1^l q1 − q2_l Γ2^l q2 + B_u u          (14)–(17)
//!   q̇2 = −Ω q1 + q2_l (Γ2^l)ᵀ q1
//!   q̇ξ = Aξ⁻¹ qξ_l Γξ^l q1                                          (26), (29)
//! ```
//!
//! **Optimal control (33)–(34).** At each sample `t_i`, from the projected plant state
//! `q_a(t_i) = q_as` (theory.md §7), over the horizon `τp` with `u` piecewise constant on
//! `Nc` intervals and `|u| ≤ u_max`:
//!
//! ```text
//!   min ∫_{t_i}^{t_i+τp} ½(q_a − q_r)ᵀQ(q_a − q_r) + ½ uᵀR u dt,
//!   Q = blkdiag(k_x1 I, k_x2 I, Kξᵀ Aξ Kξ + k_Δξ AΔξ),  R = k_u I                 (35)
//!   AΔξ = (Φξ^a(L) − Φξ^b(0))ᵀ (Φξ^a(L) − Φξ^b(0))                              (36)
//! ```
//!
//! (36) read as theory.md §6 (`qξᵀAΔξqξ` is the squared quaternion jump at the joint);
//! `q_r = [0, 0, e0]` (`qξ0,r = 1` in the unnormalised `φξ0 = ξ̄` scaling). Defaults are the
//! paper's ([`MpcSettings`]): `k_x1 = k_x2 = 0.01`, `k_Δξ = 2`, `k_u = 0.1`,
//! `Kξ = diag(1 for φξ0 and the rigid modes, 0.01 …)`, `τp = 6 s`, `τs = 0.2 s`, `Nc = 24`,
//! `|u| ≤ 5`.
//!
//! **Controllers** ([`Controller`]). NMPC: multiple-shooting SQP (Gauss–Newton, merit line
//! search) warm-started from the previous plan shifted by `τs`; on failure a retry from the
//! linear MPC plan with the paper's sub-relaxation and a Levenberg–Marquardt term; if that
//! fails too, the linear MPC plan is applied and kept for the next `fallback_hold` samples.
//! A plan whose predicted joint angle between links exceeds `plan_joint_limit_deg` (20°; the
//! modes are computed at 0°) counts as a failed attempt ([`JointMonitor`]). Linear MPC: the
//! same problem with (29) linearised at `q_r`, one QP per sample. By default the controls lie
//! on the fixed grid `kΔt`, `Δt = τp/Nc` ([`ControlGrid::Absolute`]), an off-grid sample being
//! predicted to the next grid time (the paper's `τs = 0.2 s` is not a multiple of its
//! `Δt = 0.25 s`); option [`ControlGrid::Sample`] starts each plan at its sample (see
//! docs/mpc.md).
//!
//! **Closed loops** ([`run`], [`sweep`]): the FE plant of multibody-constraints (joints as
//! hard constraints, follower loads and joint torques as inputs) or the modal model itself;
//! the paper's scenarios ([`Scenario::paper_2d`], [`Scenario::paper_3d`]); results with time
//! series, snapshots, per-sample solver reports and the summary metrics.
//!
//! # Example
//!
//! The paper's 2D scenario, coarse (6 elements per link), and one linear-MPC sample from a
//! spinning state; the control respects the bound `|u| ≤ u_max`:
//!
//! ```
//! use mpc::{Controller, ControllerKind, ControllerSettings, RomDynamics, Scenario, Setup};
//!
//! let scenario = Scenario::paper_2d(6)?;
//! let setup = Setup::new(&scenario)?;
//! let model = RomDynamics::new(&setup.rom)?;
//! let settings = ControllerSettings::of(ControllerKind::Lmpc);
//! let mut controller = Controller::new(model, &setup.weights, &scenario.mpc, &settings)?;
//! let mut x0: Vec<f64> = setup.weights.x_ref.iter().copied().collect();
//! x0[0] = 0.5; // velocity of the first (rigid) mode
//! let report = controller.step(0.0, &x0)?;
//! assert!(report.u.iter().all(|u| u.abs() <= scenario.mpc.u_max + 1e-9));
//! # Ok::<(), mpc::MpcError>(())
//! ```

mod closed_loop;
mod controller;
mod dynamics;
mod error;
mod exact_dynamics;
mod export;
mod modal_plant;
mod orientation;
mod plant;
pub mod reference;
mod scenario;
mod validity;
mod weights;

#[cfg(test)]
mod tests;

pub use closed_loop::{
    open_loop, run, sweep, Record, RunResult, RunSummary, Snapshot, COMMAND_TOLERANCE_DEG,
    ENERGY_RATIO_LIMIT,
};
pub use controller::{
    Controller, ControllerKind, ControllerSettings, SampleReport, Strategy,
    DEFAULT_PLAN_JOINT_LIMIT,
};
pub use dynamics::RomDynamics;
pub use error::{MpcError, Result};
pub use exact_dynamics::exact_joints_rom;
pub use exact_dynamics::{ExactDynamics, ModelKind};
pub use export::{export_first_sample, first_sample_problem, OcpExport};
pub use modal_plant::ModalPlant;
pub use orientation::{chord_orientation, ChordOrientation};
pub use plant::{ControlInput, PlantKind};
pub use reference::{JointCommand, ReferenceSchedule};
pub use scenario::{Scenario, Setup, MAX_PLANT_STEPS};
pub use validity::JointMonitor;
pub use weights::{ControlGrid, MpcSettings, Weights, SPATIAL_INPUT_WEIGHT};
