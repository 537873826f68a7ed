//! Optimal control problems over ODE models (paper eqs. 33–34): multiple shooting,
//! integrators with sensitivities, SQP and QPs solved with Clarabel (issue 5).

mod dynamics;
mod error;
mod integrator;
mod la;
mod ocp;
mod qp;
pub mod samples;
mod sqp;

pub use dynamics::Dynamics;
pub use error::{OcpError, Result};
pub use integrator::{Integrator, IntegratorKind, IntegratorSettings, LinearPart};
pub use ocp::Ocp;
pub use qp::QpForm;
pub use sqp::{
    Globalisation, HessianApproximation, IterationLog, SqpMode, SqpSettings, SqpSolver, SqpStats,
    SqpStatus,
};
