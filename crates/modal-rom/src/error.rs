//! The crate's error type: every fallible public function returns [`ModalError`].

use thiserror::Error;

/// Errors of the modal reduced-order model. Variants name the offending field and value.
#[non_exhaustive]
#[derive(Debug, Error)]
pub enum ModalError {
    /// A matrix or vector has the wrong shape.
    #[error("{what}: expected shape {expected}, got {got}")]
    Shape {
        /// Which argument.
        what: String,
        /// Expected shape.
        expected: String,
        /// Shape received.
        got: String,
    },
    /// A value is not finite (NaN or infinite).
    #[error("{what} contains a non-finite value at index {index}")]
    NonFinite {
        /// Which argument.
        what: String,
        /// First offending index (flattened).
        index: usize,
    },
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
    /// A factorisation or eigen decomposition failed.
    #[error("numerical failure in {stage}: {reason}")]
    Numerical {
        /// Stage that failed (e.g. `Cholesky of the reduced mass matrix`).
        stage: String,
        /// Details.
        reason: String,
    },
    /// A mode selection asks for more modes of a kind than the basis holds.
    #[error("mode selection asks for {requested} {kind} modes but the basis has {available}")]
    NotEnoughModes {
        /// Kind name.
        kind: String,
        /// Requested count.
        requested: usize,
        /// Available count.
        available: usize,
    },
    /// An input/output error while exporting or reading a model.
    #[error("I/O error on {path}: {source}")]
    Io {
        /// File path.
        path: String,
        /// Underlying error.
        source: std::io::Error,
    },
    /// An error of the multibody layer (structure, constraints).
    #[error(transparent)]
    Multibody(#[from] multibody_constraints::MultibodyError),
    /// An error of the beam layer.
    #[error(transparent)]
    Beam(#[from] intrinsic_beam::BeamError),
    /// A malformed exported file.
    #[error("malformed file {path}: {reason}")]
    Format {
        /// File path.
        path: String,
        /// What is wrong.
        reason: String,
    },
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, ModalError>;

/// Shorthand for an [`ModalError::Invalid`].
pub(crate) fn invalid(
    field: impl Into<String>,
    value: impl ToString,
    reason: impl Into<String>,
) -> ModalError {
    ModalError::Invalid { field: field.into(), value: value.to_string(), reason: reason.into() }
}

/// Shorthand for an [`ModalError::Shape`].
pub(crate) fn shape(
    what: impl Into<String>,
    expected: (usize, usize),
    got: (usize, usize),
) -> ModalError {
    ModalError::Shape {
        what: what.into(),
        expected: format!("{}x{}", expected.0, expected.1),
        got: format!("{}x{}", got.0, got.1),
    }
}
