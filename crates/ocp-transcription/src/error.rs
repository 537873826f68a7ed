//! The crate's error type.

use thiserror::Error;

/// Everything that can go wrong when building or evaluating an optimal control problem.
///
/// Construction errors (bad dimensions, bad settings) are returned by constructors;
/// numerical failures during an SQP solve are *not* errors but a [`crate::SqpStatus`].
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum OcpError {
    /// A vector or matrix has the wrong size.
    #[error("{what}: expected dimension {expected}, found {found}")]
    Dimension {
        /// Which argument.
        what: &'static str,
        /// Expected size.
        expected: usize,
        /// Size found.
        found: usize,
    },
    /// A setting or problem parameter is out of its valid range.
    #[error("invalid {field} = {value}: {reason}")]
    InvalidSetting {
        /// Field name.
        field: &'static str,
        /// Offending value, formatted.
        value: String,
        /// Why it is invalid.
        reason: &'static str,
    },
    /// The dynamics returned a NaN or infinite value.
    #[error("non-finite value from the dynamics in {stage}")]
    NonFiniteDynamics {
        /// Where it appeared (`rhs`, `jacobian`, `state`, `hessian`).
        stage: &'static str,
    },
    /// The Newton iteration of an implicit integrator did not converge.
    #[error(
        "implicit step: Newton did not converge in {iterations} iterations (residual {residual:e})"
    )]
    NewtonFailed {
        /// Iterations performed.
        iterations: usize,
        /// Last residual (max norm).
        residual: f64,
    },
    /// A Newton matrix or Hessian could not be factorised.
    #[error("singular or indefinite matrix in {what}")]
    Singular {
        /// Which matrix.
        what: &'static str,
    },
    /// The requested combination of options is not available.
    #[error("unsupported: {what}")]
    Unsupported {
        /// What was asked for.
        what: &'static str,
    },
    /// Clarabel rejected the QP data at setup.
    #[error("QP setup failed: {message}")]
    QpSetup {
        /// Clarabel's message.
        message: String,
    },
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, OcpError>;

pub(crate) fn check_dim(what: &'static str, expected: usize, found: usize) -> Result<()> {
    if expected == found {
        Ok(())
    } else {
        Err(OcpError::Dimension { what, expected, found })
    }
}

pub(crate) fn invalid(
    field: &'static str,
    value: impl std::fmt::Display,
    reason: &'static str,
) -> OcpError {
    OcpError::InvalidSetting { field, value: value.to_string(), reason }
}
