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
//! search) warm-started from the previous plan shifted by `τs`. By default one SQP iteration
//! per sample (real-time iteration, [`ControllerSettings::default`]); the full SQP
//! ([`ControllerSettings::full_sqp`]) iterates to its KKT tolerance and on failure retries
//! from the linear MPC plan with the paper's sub-relaxation and a Levenberg–Marquardt term.
//! If the NMPC fails, the linear MPC plan is applied and kept for the next `fallback_hold`
//! samples.
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
//! assert!(report.u.iter().all(|u| u.abs() <= scenario.mpc.cost.u_max + 1e-9));
//! # Ok::<(), mpc::MpcError>(())
//! ```
//!
//! # Closed loops: [`run`]
//!
//! A [`Scenario`] (here the paper's 2D two-link, coarse, for one second) becomes a [`Setup`]
//! (modes, reduced model, weights) once; [`run`] then simulates one closed loop at a
//! disturbance `ω0` with the default controller (the real-time NMPC,
//! [`ControllerSettings::default`]) on the FE plant or, as here, the modal model itself. The
//! result holds the time series, per-sample solver reports, snapshots and the summary:
//!
//! ```
//! use mpc::{run, ControllerSettings, PlantKind, Scenario, Setup, Strategy};
//!
//! let mut scenario = Scenario::paper_2d(4)?;
//! scenario.duration = 1.0;
//! let setup = Setup::new(&scenario)?;
//! let result = run(&setup, 0.5, &ControllerSettings::default(), PlantKind::Rom)?;
//! assert!(result.summary.error.is_none());
//! assert_eq!(result.samples.len(), 5); // τs = 0.2 s
//! assert!(result.samples.iter().all(|s| s.strategy == Strategy::Sqp));
//! assert_eq!(result.records.len(), 21); // every 0.05 s, both ends
//! // the controller brakes the rotation: the rigid rate is below its initial value
//! assert!(result.summary.rigid_rate_ratio < 1.0, "{:?}", result.summary);
//! // the snapshots carry positions and section orientations of every node
//! let s = &result.snapshots[0];
//! assert_eq!(s.positions.len(), 2);
//! assert_eq!(s.orientations[1].len(), s.positions[1].len());
//! # Ok::<(), mpc::MpcError>(())
//! ```
//!
//! # Controller settings: [`ControllerSettings`]
//!
//! The default is the real-time NMPC (one SQP iteration per sample); the full SQP, the
//! spatial real-time variant and the linear MPC are named constructors. Every setting is
//! checked by `validate`, whose error names the field:
//!
//! ```
//! use mpc::{ControllerKind, ControllerSettings};
//!
//! let rti = ControllerSettings::default();
//! assert!(rti.real_time_iteration && rti.retry_relaxation.is_none());
//! let full = ControllerSettings::full_sqp();
//! assert!(!full.real_time_iteration && full.retry_relaxation == Some(0.5));
//! assert_eq!(ControllerSettings::of(ControllerKind::Lmpc).kind, ControllerKind::Lmpc);
//! assert!(ControllerSettings::real_time_spatial().validate().is_ok());
//! let bad = ControllerSettings { retry_relaxation: Some(1.5), ..full };
//! assert!(bad.validate().unwrap_err().to_string().contains("retry_relaxation"));
//! ```
//!
//! # Scenarios: [`Scenario`], [`Setup`]
//!
//! A scenario is plain data (structure, inputs, modes, timing, [`MpcSettings`]); its
//! `validate` (also run by [`Setup::new`]) names the field of a wrong value:
//!
//! ```
//! use mpc::{MpcSettings, Scenario, Setup};
//!
//! let mut scenario = Scenario::paper_3d(2)?;
//! assert_eq!(scenario.inputs.len(), 5);
//! assert_eq!(scenario.mpc, MpcSettings::default()); // the paper's weights and timing
//! scenario.duration = -1.0;
//! let e = Setup::new(&scenario).unwrap_err();
//! assert!(e.to_string().contains("duration"), "{e}");
//! # Ok::<(), mpc::MpcError>(())
//! ```
//!
//! # Sweeps and open loops: [`sweep`], [`open_loop`]
//!
//! [`sweep`] runs several `ω0` in parallel (results in input order); [`open_loop`] replays
//! a given input history on a plant, for comparing the modal model with the FE plant:
//!
//! ```
//! use mpc::{open_loop, sweep, ControllerKind, ControllerSettings, PlantKind, Scenario, Setup};
//!
//! let mut scenario = Scenario::paper_2d(4)?;
//! scenario.duration = 0.4;
//! let setup = Setup::new(&scenario)?;
//! let lmpc = ControllerSettings::of(ControllerKind::Lmpc);
//! let runs = sweep(&setup, &[0.25, 0.5], &lmpc, PlantKind::Rom, &|| {});
//! let omegas: Vec<f64> = runs.iter().map(|r| r.as_ref().unwrap().summary.omega0).collect();
//! assert_eq!(omegas, [0.25, 0.5]);
//!
//! let inputs = vec![vec![0.0; scenario.inputs.len()]; 4]; // 4 output intervals, no control
//! let fe = open_loop(&setup, 0.5, &inputs, PlantKind::Fe)?;
//! let rom = open_loop(&setup, 0.5, &inputs, PlantKind::Rom)?;
//! assert_eq!((fe.len(), rom.len()), (5, 5));
//! // uncontrolled, the structure keeps turning (tip 2 m from the root at 0.5 rad/s: 0.2 m
//! // in 0.2 s), and the modal model follows the FE plant closely over this short time
//! let moved = (0..3).map(|k| (fe[4].tip[k] - fe[0].tip[k]).powi(2)).sum::<f64>().sqrt();
//! assert!((moved - 0.2).abs() < 0.01, "{moved}");
//! assert!((0..3).all(|k| (fe[4].tip[k] - rom[4].tip[k]).abs() < 1e-2));
//! # Ok::<(), mpc::MpcError>(())
//! ```
//!
//! # The first sample's problem: [`first_sample_problem`], [`export_first_sample`]
//!
//! The optimal control problem (33)–(34) of the first sample as data, for other solvers
//! ([`export_first_sample`] also writes it with the modal model to a folder):
//!
//! ```
//! use mpc::{first_sample_problem, ControllerSettings, Scenario, Setup};
//!
//! let setup = Setup::new(&Scenario::paper_2d(4)?)?;
//! let p = first_sample_problem(&setup, 1.0, &ControllerSettings::default())?;
//! assert_eq!(p.x0.len(), setup.rom.n_state());
//! assert_eq!((p.q.len(), p.r.len()), (p.x0.len(), 3));
//! assert_eq!(p.intervals, 24); // Nc
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
    Controller, ControllerKind, ControllerSettings, InitialGuess, SampleReport, SolveTiming,
    Strategy, DEFAULT_PLAN_JOINT_LIMIT, REAL_TIME_NEWTON_TOLERANCE,
};
pub use dynamics::RomDynamics;
pub use error::{MpcError, Result};
pub use exact_dynamics::exact_joints_rom;
pub use exact_dynamics::{ExactDynamics, ModelKind};
pub use export::{
    export_first_sample, export_first_sample_exact, first_sample_exact, first_sample_problem,
    ExactFirstSample, OcpExport,
};
pub use modal_plant::ModalPlant;
pub use orientation::{chord_orientation, ChordOrientation};
pub use plant::{ControlInput, PlantKind};
pub use reference::{JointCommand, ReferenceSchedule};
pub use scenario::{Scenario, Setup, MAX_PLANT_STEPS};
pub use validity::JointMonitor;
pub use weights::{ControlGrid, CostWeights, MpcSettings, Timing, Weights, SPATIAL_INPUT_WEIGHT};
