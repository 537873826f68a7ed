//! The crate's error type: every user- or data-caused failure is a [`BeamError`].

use thiserror::Error;

/// Everything that can go wrong when building or running a beam model.
///
/// Variants carry the offending field and value so that messages say what to fix.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum BeamError {
    /// A number that must be finite is NaN or infinite.
    #[error("{field} has a non-finite entry {value} at {index}")]
    NonFinite {
        /// Which input (e.g. `section.mass`).
        field: String,
        /// Position of the entry (flattened index or description).
        index: String,
        /// The value found.
        value: f64,
    },
    /// A matrix that must be symmetric is not.
    #[error("{field} is not symmetric: entry ({row},{col}) = {a} but ({col},{row}) = {b}")]
    NotSymmetric {
        /// Which matrix.
        field: String,
        /// Row of the first entry.
        row: usize,
        /// Column of the first entry.
        col: usize,
        /// Value at (row, col).
        a: f64,
        /// Value at (col, row).
        b: f64,
    },
    /// A matrix that must be positive (semi)definite is not.
    #[error("{field} is not {requirement} (smallest eigenvalue or pivot {value})")]
    NotDefinite {
        /// Which matrix.
        field: String,
        /// What was required, e.g. `positive definite on the non-rigid directions`.
        requirement: String,
        /// The offending eigenvalue or pivot.
        value: f64,
    },
    /// A direction stated rigid/massless has a non-zero entry, or a zero direction was not stated.
    #[error("{field}: direction {direction} {problem}")]
    InconsistentDirection {
        /// Which matrix.
        field: String,
        /// Component index 0..6.
        direction: usize,
        /// What is inconsistent.
        problem: String,
    },
    /// A length (beam, element) is not positive.
    #[error("{field} must be positive, got {value}")]
    NonPositiveLength {
        /// Which length (e.g. `element 3 length`).
        field: String,
        /// The value found.
        value: f64,
    },
    /// A mesh must have at least one element.
    #[error("a mesh needs at least one element (got {n_elements})")]
    NoElements {
        /// Number of elements asked for.
        n_elements: usize,
    },
    /// Node coordinates must strictly increase.
    #[error("node coordinates must strictly increase: s[{index}] = {value} after {previous}")]
    NonIncreasingNodes {
        /// Index of the offending node.
        index: usize,
        /// Its coordinate.
        value: f64,
        /// The previous coordinate.
        previous: f64,
    },
    /// A time step or duration must be positive and finite.
    #[error("{field} must be positive and finite, got {value}")]
    NonPositiveTime {
        /// Which quantity (e.g. `dt`).
        field: String,
        /// The value found.
        value: f64,
    },
    /// A load, output or condition refers to a node that does not exist.
    #[error("{what} refers to node {node}, but the beam has nodes 0..={last}")]
    NodeOutOfRange {
        /// What refers to the node.
        what: String,
        /// The node index given.
        node: usize,
        /// The last valid node index.
        last: usize,
    },
    /// A slice has the wrong length.
    #[error("{what}: expected length {expected}, got {got}")]
    DimensionMismatch {
        /// Which argument.
        what: String,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// A planar beam was given spatial data (out-of-plane coupling, curvature, load).
    #[error("planar beam: {what} has an out-of-plane entry {value} at {index}")]
    NotPlanar {
        /// Which input.
        what: String,
        /// Entry description.
        index: String,
        /// The value found.
        value: f64,
    },
    /// A setting is outside its valid range.
    #[error("setting {field} = {value} is invalid: {reason}")]
    InvalidSetting {
        /// Setting name.
        field: String,
        /// Value given.
        value: f64,
        /// Valid range.
        reason: String,
    },
    /// The problem cannot be posed as an ODE (needed by explicit integrators).
    #[error("not an ODE: {reason}")]
    NotAnOde {
        /// Why.
        reason: String,
    },
    /// A sparse or dense factorisation failed (singular system).
    #[error("linear solve failed: {reason}")]
    LinearSolve {
        /// Solver message.
        reason: String,
    },
    /// Newton's method did not converge.
    #[error("Newton did not converge in {iterations} iterations (residual {residual:e}, tolerance {tolerance:e})")]
    NewtonFailed {
        /// Iterations done.
        iterations: usize,
        /// Final residual norm.
        residual: f64,
        /// Tolerance asked for.
        tolerance: f64,
    },
    /// The state became non-finite during a computation.
    #[error("non-finite value in {what}")]
    NonFiniteState {
        /// Where it was detected.
        what: String,
    },
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, BeamError>;

/// Checks that `value` is finite, naming the field.
pub(crate) fn check_finite(field: &str, index: impl Into<String>, value: f64) -> Result<()> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(BeamError::NonFinite { field: field.to_string(), index: index.into(), value })
    }
}

/// Checks a slice length.
pub(crate) fn check_len(what: &str, expected: usize, got: usize) -> Result<()> {
    if expected == got {
        Ok(())
    } else {
        Err(BeamError::DimensionMismatch { what: what.to_string(), expected, got })
    }
}

/// `x > 0` and finite (false for NaN).
pub(crate) fn positive_finite(x: f64) -> bool {
    x > 0.0 && x.is_finite()
}
