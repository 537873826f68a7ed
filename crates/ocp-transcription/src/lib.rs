//! Optimal control problems over ODE models (paper eqs. 33–34): multiple shooting,
//! integrators with exact sensitivities, SQP with QPs solved by a dense interior point or
//! Clarabel. This crate knows nothing about beams: a model is anything that
//! implements [`Dynamics`].
//!
//! # The problem (33)–(34)
//!
//! ```text
//!   min_u  ∫_0^τp V(x(t), u(t)) dt,   V = ½(x − x_r)ᵀQ(x − x_r) + ½(u − u_r)ᵀR(u − u_r)   (34)
//!   s.t.   ẋ = f(x, u),  x(0) = x0,  u_min ≤ u ≤ u_max,  (optionally x_min ≤ x ≤ x_max)   (33)
//! ```
//!
//! with `u` piecewise constant on `Nc` equal intervals of length `Δt = τp/Nc` (independent of
//! any sampling time). [`Ocp`] holds `τp`, `Nc`, `Q`, `R`, an optional terminal weight `P`,
//! the references and the bounds.
//!
//! # Transcription
//!
//! Multiple shooting with one node per control interval: variables `s_0 … s_N`, `u_0 … u_{N−1}`
//! (`N = Nc`), constraints `s_0 = x0` and `s_{k+1} = Φ(s_k, u_k)`, where `Φ` is one
//! [`Integrator`] pass over the interval (RK4, implicit midpoint or Lawson RK4 with `n`
//! substeps, fixed or chosen per interval from the state by an error table,
//! [`AdaptiveSubsteps`]; never written as NLP constraints). The cost is
//!
//! ```text
//!   J = Σ_k c_k Δt ½(s_k − x_r)ᵀQ(s_k − x_r) + Σ_k Δt ½(u_k − u_r)ᵀR(u_k − u_r) + ½(s_N − x_r)ᵀP(s_N − x_r),
//! ```
//!
//! trapezoidal in the state (`c_0 = c_N = ½`, else 1), exact in the piecewise-constant control.
//!
//! # SQP
//!
//! [`SqpSolver`] linearises (`A_k = ∂Φ/∂s`, `B_k = ∂Φ/∂u` exact for the discrete map,
//! defects `d_k = Φ(s_k, u_k) − s_{k+1}`), solves
//!
//! ```text
//!   min ½ΔwᵀHΔw + ∇JᵀΔw  s.t.  Δs_0 = x0 − s_0,  Δs_{k+1} = A_kΔs_k + B_kΔu_k + d_k,  bounds,
//! ```
//!
//! with `H` the Gauss–Newton (cost) Hessian or the exact Hessian of the Lagrangian
//! ([`HessianApproximation`]), in condensed form (dense interior point on the control box, or
//! Clarabel when there are state bounds) or in sparse multiple-shooting form with Clarabel
//! ([`QpForm`]); steps by merit line search, the paper's fixed relaxation `w ← w + αΔw`, or
//! full steps ([`Globalisation`]); stops on the KKT residual. Real-time iteration and the
//! linear–quadratic (linear MPC) mode are [`SqpMode`]s; [`SqpSolver::shift`] /
//! [`SqpSolver::shift_time`] warm-start the next sample. A solve never panics on a numerical
//! failure: it returns [`SqpStats`] with a [`SqpStatus`] and counters.
//!
//! ```
//! use ocp_transcription::{samples::CartPole, Ocp, SqpSettings, SqpSolver, SqpStatus};
//! let mut ocp = Ocp::new(4, 1, 1.5, 30)?;
//! ocp.u_min[0] = -25.0;
//! ocp.u_max[0] = 25.0;
//! let mut solver = SqpSolver::new(CartPole::default(), ocp, SqpSettings::default())?;
//! let x0 = [0.0, 0.2, 0.0, 0.0];
//! solver.initialize_constant(&x0, &[0.0])?;
//! let stats = solver.solve(&x0)?;
//! assert_eq!(stats.status, SqpStatus::Solved);
//! let u0 = solver.first_control(); // apply, then solver.shift_time(τs) and solve again
//! # let _ = u0;
//! # Ok::<(), ocp_transcription::OcpError>(())
//! ```
//!
//! Workspaces are allocated by the constructors; the SQP loop allocates only inside Clarabel
//! (its setup is rebuilt per QP) and in rayon's scheduling when
//! [`SqpSettings::parallel_intervals`] is on. See `docs/ocp-transcription.md` for the
//! measured error/cost tables and the decisions.

mod clock;
mod dynamics;
mod error;
mod integrator;
mod la;
mod ocp;
mod qp;
mod quadratic;
pub mod samples;
mod sqp;

pub use clock::{process_cpu_time, thread_cpu_time, thread_cpu_timed};
pub use dynamics::Dynamics;
pub use error::{OcpError, Result};
pub use integrator::{
    interval_error, AdaptiveSubsteps, Evaluations, Integrator, IntegratorKind, IntegratorSettings,
    LinearPart, MidpointRecord, TailSubsteps, SIMPLIFIED_NEWTON_MAX_RATE,
};
pub use ocp::Ocp;
pub use qp::QpForm;
pub use quadratic::QuadraticTerms;
pub use sqp::{
    Globalisation, HessianApproximation, IterationLog, SqpMode, SqpSettings, SqpSolver, SqpStats,
    SqpStatus, Start, AUTO_SPARSE_CONDITION, CONVERGE_SWITCH_KKT, PROJECTION_FLOOR,
};
