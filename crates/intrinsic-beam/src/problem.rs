//! Single-beam problems: end conditions closing the `2k` end unknowns (the data that
//! the step system assembles and the implicit midpoint driver integrates).
//!
//! End rows (one per active component and end), evaluated for the step `t → t + dt`:
//! * force component `a` (free end or applied end load `F`, local frame of the end node):
//!   `x2_L[a] = −F_a(t + dt/2)` at s = 0 and `x2_R[a] = +F_a(t + dt/2)` at s = L (node 0's
//!   equation contains `−x2_L`, node N's `+x2_R`, so `±x2` acts on the end node as `F`);
//! * prescribed velocity component `a` (clamped, pinned translations, prescribed motion):
//!   `x1_end[a](t + dt) = g_a(t + dt)` (the midpoint value is then the average of the end-point
//!   values; for a massless component, whose slot holds the midpoint value, `g_a(t + dt/2)`);
//!   the matching `x2_end[a]` is the reaction.

use nalgebra::Vector6;

use crate::beam::Beam;
use crate::error::Result;
use crate::loads::{Amplitude, Loads};

/// Boundary condition at one end of a single beam (all values in the end node's local frame).
#[derive(Clone, Debug, PartialEq)]
pub enum EndCondition {
    /// No force, no moment (`x2_end = 0`).
    Free,
    /// An applied external force/moment `[F, M]` at the end (follower), times `amplitude`.
    Force {
        /// `[force, moment]`, local frame.
        value: Vector6<f64>,
        /// Time history.
        amplitude: Amplitude,
    },
    /// All velocities zero.
    Clamped,
    /// Translational velocities zero, moments zero (rotation free).
    Pinned,
    /// Prescribed end velocities `x1_end = value · amplitude(t)`.
    Motion {
        /// `[v, ω]`, local frame.
        value: Vector6<f64>,
        /// Time history.
        amplitude: Amplitude,
    },
    /// Per component: `velocity[i]` prescribes `x1[i] = value[i] a(t)`, otherwise the applied
    /// force/moment component is `value[i] a(t)`.
    Mixed {
        /// Which components have prescribed velocity.
        velocity: [bool; 6],
        /// Prescribed velocity or applied force per component.
        value: Vector6<f64>,
        /// Time history.
        amplitude: Amplitude,
    },
}

impl EndCondition {
    /// `(velocity mask, value, amplitude)` of any condition.
    pub fn resolve(&self) -> ([bool; 6], Vector6<f64>, Amplitude) {
        match self {
            Self::Free => ([false; 6], Vector6::zeros(), Amplitude::Constant),
            Self::Force { value, amplitude } => ([false; 6], *value, amplitude.clone()),
            Self::Clamped => ([true; 6], Vector6::zeros(), Amplitude::Constant),
            Self::Pinned => {
                ([true, true, true, false, false, false], Vector6::zeros(), Amplitude::Constant)
            }
            Self::Motion { value, amplitude } => ([true; 6], *value, amplitude.clone()),
            Self::Mixed { velocity, value, amplitude } => (*velocity, *value, amplitude.clone()),
        }
    }
}

/// Which end of a beam.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum End {
    /// s = 0.
    Left,
    /// s = L.
    Right,
}

/// One beam with its two end conditions and loads.
#[derive(Clone, Debug)]
pub struct BeamProblem {
    /// The discretised beam.
    pub beam: Beam,
    /// Condition at s = 0.
    pub left: EndCondition,
    /// Condition at s = L.
    pub right: EndCondition,
    /// External loads (may be modified between steps).
    pub loads: Loads,
}

impl BeamProblem {
    /// Builds and validates (loads on existing nodes, planar data for planar beams).
    ///
    /// ```
    /// use intrinsic_beam::{Beam, BeamProblem, Components, EndCondition, Loads, Mesh, Section};
    ///
    /// let beam = Beam::new(Section::paper_2d(), Mesh::uniform(1.0, 4)?, Components::Planar)?;
    /// let cantilever = BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())?;
    /// assert_eq!(cantilever.beam.n_elements(), 4);
    /// # Ok::<(), intrinsic_beam::BeamError>(())
    /// ```
    pub fn new(beam: Beam, left: EndCondition, right: EndCondition, loads: Loads) -> Result<Self> {
        let p = Self { beam, left, right, loads };
        p.validate()?;
        Ok(p)
    }

    /// Checks loads and end conditions against the beam.
    pub fn validate(&self) -> Result<()> {
        self.loads.validate(self.beam.components(), self.beam.n_nodes())?;
        for (name, c) in [("left end", &self.left), ("right end", &self.right)] {
            let (_, value, amp) = c.resolve();
            for i in 0..6 {
                crate::error::check_finite(name, format!("value {i}"), value[i])?;
            }
            amp.validate(name)?;
            self.beam.components().check_vector(name, &value)?;
        }
        Ok(())
    }

    /// Size of the single-beam step system, `k(2N+3)`.
    pub fn dim(&self) -> usize {
        self.beam.dim()
    }

    /// For end `end` and active component `a`: the unknown the end row constrains.
    pub fn end_unknown(&self, end: End, a: usize) -> usize {
        let beam = &self.beam;
        let (cond, node) = match end {
            End::Left => (&self.left, 0),
            End::Right => (&self.right, beam.n_elements()),
        };
        let i6 = beam.components().indices()[a];
        let (vel, _, _) = cond.resolve();
        if vel[i6] {
            beam.x1_index(node, a)
        } else {
            match end {
                End::Left => beam.left_index(a),
                End::Right => beam.right_index(a),
            }
        }
    }

    /// The value the end row sets the constrained unknown to, for a step from `time` by `dt`.
    pub fn end_target(&self, end: End, a: usize, time: f64, dt: f64) -> f64 {
        let beam = &self.beam;
        let cond = match end {
            End::Left => &self.left,
            End::Right => &self.right,
        };
        let i6 = beam.components().indices()[a];
        let (vel, value, amp) = cond.resolve();
        if vel[i6] {
            let col = self.end_unknown(end, a);
            let t = if beam.is_algebraic(col) { time + 0.5 * dt } else { time + dt };
            value[i6] * amp.at(t)
        } else {
            let sign = if end == End::Left { -1.0 } else { 1.0 };
            sign * value[i6] * amp.at(time + 0.5 * dt)
        }
    }

    /// Pattern of the full step system (beam rows, then `k` left and `k` right end rows).
    pub fn step_pattern(&self) -> Vec<(usize, usize)> {
        let mut pattern = Vec::with_capacity(self.beam.jacobian_nnz() + 2 * self.beam.k());
        self.beam.jacobian_pattern(0, 0, &mut pattern);
        let rows = self.beam.n_rows();
        let k = self.beam.k();
        for a in 0..k {
            pattern.push((rows + a, self.end_unknown(End::Left, a)));
        }
        for a in 0..k {
            pattern.push((rows + k + a, self.end_unknown(End::Right, a)));
        }
        pattern
    }
}
