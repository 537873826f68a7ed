//! The crate's error type: every fallible public function returns [`MpcError`].

use thiserror::Error;

/// Errors of the MPC layer. Numerical failures of a solve are *not* errors (they are a
/// per-sample status in the results); these are construction and data errors, and failures of
/// the layers below that stop a run.
#[non_exhaustive]
#[derive(Debug, Error)]
pub enum MpcError {
    /// A setting or argument is out of its valid range.
    #[error("invalid {field} = {value}: {reason}")]
    Invalid {
        /// Name of the field or argument.
        field: String,
        /// The value received, formatted.
        value: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The optimal control layer rejected a problem or setting.
    #[error(transparent)]
    Ocp(#[from] ocp_transcription::OcpError),
    /// The modal layer failed (modes, reduced model, projection).
    #[error(transparent)]
    Modal(#[from] modal_rom::ModalError),
    /// The FE plant failed (construction, a step's Newton iteration).
    #[error(transparent)]
    Plant(#[from] multibody_constraints::MultibodyError),
    /// The reduced-model plant produced a non-finite state at time `t`.
    #[error("the reduced-model plant diverged (non-finite state) at t = {t}")]
    PlantDiverged {
        /// Time of the failing sample (s).
        t: f64,
    },
}

impl MpcError {
    /// The same error with the value of an [`MpcError::Invalid`] replaced by `value`.
    pub(crate) fn with_value(self, value: impl std::fmt::Display) -> MpcError {
        match self {
            MpcError::Invalid { field, reason, .. } => {
                MpcError::Invalid { field, value: value.to_string(), reason }
            }
            other => other,
        }
    }

    /// The same error with the reason of an [`MpcError::Invalid`] rewritten by `f`.
    pub(crate) fn with_reason(self, f: impl FnOnce(String) -> String) -> MpcError {
        match self {
            MpcError::Invalid { field, value, reason } => {
                MpcError::Invalid { field, value, reason: f(reason) }
            }
            other => other,
        }
    }

    /// The same error with its field named inside `owner` (`horizon` → `mpc.horizon`), for
    /// the checks a settings struct runs on the structs it holds. Other variants pass through.
    pub(crate) fn within(self, owner: &str) -> MpcError {
        match self {
            MpcError::Invalid { field, value, reason } => {
                MpcError::Invalid { field: format!("{owner}.{field}"), value, reason }
            }
            MpcError::Ocp(ocp_transcription::OcpError::InvalidSetting { field, value, reason }) => {
                MpcError::Invalid {
                    field: format!("{owner}.{field}"),
                    value,
                    reason: reason.to_string(),
                }
            }
            MpcError::Plant(multibody_constraints::MultibodyError::BadSetting {
                field,
                value,
                reason,
            }) => MpcError::Invalid {
                field: format!("{owner}.{field}"),
                value: value.to_string(),
                reason: reason.to_string(),
            },
            other => other,
        }
    }
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, MpcError>;

/// An [`MpcError::Invalid`] naming `field` and `value`.
pub(crate) fn invalid(
    field: impl Into<String>,
    value: impl std::fmt::Display,
    reason: impl Into<String>,
) -> MpcError {
    MpcError::Invalid { field: field.into(), value: value.to_string(), reason: reason.into() }
}
