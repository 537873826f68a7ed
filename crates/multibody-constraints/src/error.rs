//! The error type of the crate: bad topology, bad joint data, failed solves.

use std::fmt;

use thiserror::Error;

/// The item of a structure (or of the caller's input) an error is about; its `Display` is the
/// label in the error message (``joint `elbow` ``, ``support `root` ``, ``beam `link1` ``,
/// ``placement of beam `link2` ``, or the caller's own words).
#[non_exhaustive]
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Owner {
    /// A joint, by name.
    Joint(String),
    /// A support, by name.
    Support(String),
    /// A beam, by name.
    Beam(String),
    /// The placement of a beam (by the beam's name).
    Placement(String),
    /// An entry of the caller's input, named in the caller's words (e.g. a file key).
    Input(String),
}

impl fmt::Display for Owner {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Owner::Joint(n) => write!(f, "joint `{n}`"),
            Owner::Support(n) => write!(f, "support `{n}`"),
            Owner::Beam(n) => write!(f, "beam `{n}`"),
            Owner::Placement(n) => write!(f, "placement of beam `{n}`"),
            Owner::Input(s) => f.write_str(s),
        }
    }
}

/// Everything that can go wrong when building or running a structure.
#[non_exhaustive]
#[derive(Debug, Error)]
pub enum MultibodyError {
    /// A beam-level error (section, mesh, load, step) from `intrinsic-beam`.
    #[error(transparent)]
    Beam(#[from] intrinsic_beam::BeamError),
    /// A joint or support names a beam that the structure does not have.
    #[error("{owner}: unknown beam `{beam}` (the structure has: {known})")]
    UnknownBeam {
        /// The joint, support or placement that refers to it.
        owner: Owner,
        /// The name given.
        beam: String,
        /// The beams that exist, comma separated.
        known: String,
    },
    /// A beam end given as text is neither `start` nor `end`.
    #[error("{owner}: unknown beam end `{end}` (allowed: `start` (s = 0) or `end` (s = L))")]
    UnknownEnd {
        /// The joint or support that refers to it.
        owner: Owner,
        /// The text given.
        end: String,
    },
    /// A beam end takes part in two joints/supports (or twice in one joint).
    #[error("beam `{beam}` end `{end}` is used twice: by {first} and by {second}")]
    EndUsedTwice {
        /// Beam name.
        beam: String,
        /// `start` or `end`.
        end: String,
        /// First user.
        first: Owner,
        /// Second user.
        second: Owner,
    },
    /// Two beams, joints or supports share a name.
    #[error("duplicate name `{name}` ({what})")]
    DuplicateName {
        /// The name.
        name: String,
        /// What kind of item.
        what: &'static str,
    },
    /// A joint with fewer than two ends.
    #[error("joint `{joint}` ties {count} beam end(s); a joint needs at least 2 (use a support for one end against the ground)")]
    TooFewEnds {
        /// Joint name.
        joint: String,
        /// Number of ends given.
        count: usize,
    },
    /// The beams do not form one connected structure.
    #[error("the structure is not connected: {groups} separate groups ({detail}); join them or allow disconnected structures explicitly")]
    NotConnected {
        /// Number of connected groups.
        groups: usize,
        /// The beams of each group.
        detail: String,
    },
    /// An axis or direction of zero length (or not finite).
    #[error("{owner}: axis {axis:?} has zero length or is not finite")]
    ZeroAxis {
        /// The joint, support or placement.
        owner: Owner,
        /// The axis given.
        axis: [f64; 3],
    },
    /// A joint's axes in a planar structure leave the plane of motion.
    #[error("{owner}: {what} is not compatible with a planar structure (motion in the e1–e3 plane, rotation about e2)")]
    NotPlanar {
        /// The joint, support or placement.
        owner: Owner,
        /// What is wrong.
        what: String,
    },
    /// The constraints are redundant or conflicting: the linearised constrained system is
    /// rank deficient.
    #[error(
        "redundant or conflicting constraints (rank deficiency {deficiency}) involving: {involved}"
    )]
    RedundantConstraints {
        /// Number of dependent rows.
        deficiency: usize,
        /// The joints and supports whose rows take part in the dependency.
        involved: String,
    },
    /// A placement refers to a joint that cannot place the beam.
    #[error("beam `{beam}`: bad placement: {reason}")]
    BadPlacement {
        /// Beam name.
        beam: String,
        /// Why.
        reason: String,
    },
    /// An input (load, torque) that the structure cannot take.
    #[error("input `{input}`: {reason}")]
    BadInput {
        /// Input description.
        input: String,
        /// Why.
        reason: String,
    },
    /// A setting out of range.
    #[error("setting `{field}` = {value}: {reason}")]
    BadSetting {
        /// Field name.
        field: &'static str,
        /// The value given.
        value: f64,
        /// The allowed range.
        reason: &'static str,
    },
    /// A numeric quantity given to the structure is not finite.
    #[error("{what} is not finite: {value}")]
    NotFinite {
        /// What.
        what: String,
        /// The value.
        value: f64,
    },
    /// A joint torque about an axis that is not a free rotation axis of the joint, or no axis
    /// given for a joint with several (or no) free rotation axes.
    #[error("`{joint}`: axis {axis:?} is not a free rotation axis (free rotation axes: {free:?}; give one when there are several)")]
    NotFreeRotationAxis {
        /// Joint or support name.
        joint: String,
        /// The requested axis (index among the joint's active axes), if any.
        axis: Option<usize>,
        /// Indices of the joint's free rotation axes.
        free: Vec<usize>,
    },
    /// A linear solve failed (singular system).
    #[error("linear solve failed: {0}")]
    LinearSolve(String),
    /// Newton's method did not converge in a time step.
    #[error("Newton did not converge at t = {time}: residual {residual:e} after {iterations} iterations")]
    NewtonFailed {
        /// Time at the start of the step.
        time: f64,
        /// Final residual norm.
        residual: f64,
        /// Iterations spent.
        iterations: usize,
    },
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, MultibodyError>;
