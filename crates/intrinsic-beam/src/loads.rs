//! External loads: point and distributed, follower (local frame) or dead (global frame).
//!
//! A load value is a 6-vector `[force, moment]`. Follower loads act in the local frame of the
//! node they are applied to; dead loads are given in the global frame and rotated into the
//! local frame with the node's rotation, `Tᵀ(ξ) F` (eq. 9). In an implicit-midpoint step the
//! rotation is the step's midpoint rotation `T(ξ_mid)`, `ξ_mid = exp(dt/2 U(ω_mid)) ξ_n`; with
//! positions advanced as `r⁺ = r + dt T(ξ_mid) v_mid`, the work of a constant dead force is then
//! exactly `F·(r⁺ − r)` (so gravity conserves `ε − F·r` to solver tolerance).
//! Distributed loads (`f1` of eq. 1, per unit length) are lumped with the node weights `w_n`.

use nalgebra::Vector6;

use crate::components::Components;
use crate::error::{check_finite, BeamError, Result};

/// Frame in which a load's components are given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LoadFrame {
    /// Local (body) frame of the node: follows the deformation.
    Follower,
    /// Global (inertial) frame: fixed direction (gravity, fixed-direction forces).
    Dead,
}

/// Time history multiplying a load's value.
#[derive(Clone, Debug, PartialEq)]
pub enum Amplitude {
    /// 1 at all times.
    Constant,
    /// Linear ramp from 0 at `t = 0` to 1 at `t = duration`, then 1.
    Ramp {
        /// Ramp duration (> 0).
        duration: f64,
    },
    /// Piecewise linear through `(t, a)` points (increasing `t`), held constant outside.
    Table(Vec<(f64, f64)>),
}

impl Amplitude {
    /// The amplitude at time `t`.
    pub fn at(&self, t: f64) -> f64 {
        match self {
            Self::Constant => 1.0,
            Self::Ramp { duration } => (t / duration).clamp(0.0, 1.0),
            Self::Table(points) => {
                let Some(first) = points.first() else { return 0.0 };
                if t <= first.0 {
                    return first.1;
                }
                for w in points.windows(2) {
                    let ((t0, a0), (t1, a1)) = (w[0], w[1]);
                    if t <= t1 {
                        return a0 + (a1 - a0) * (t - t0) / (t1 - t0);
                    }
                }
                points[points.len() - 1].1
            }
        }
    }

    /// Checks: ramp duration positive, table finite with strictly increasing times.
    pub fn validate(&self, what: &str) -> Result<()> {
        match self {
            Self::Constant => Ok(()),
            Self::Ramp { duration } => {
                if *duration > 0.0 && duration.is_finite() {
                    Ok(())
                } else {
                    Err(BeamError::NonPositiveTime {
                        field: format!("{what}.ramp duration"),
                        value: *duration,
                    })
                }
            }
            Self::Table(points) => {
                for (i, (t, a)) in points.iter().enumerate() {
                    check_finite(what, format!("table time {i}"), *t)?;
                    check_finite(what, format!("table value {i}"), *a)?;
                    if i > 0 && *t <= points[i - 1].0 {
                        return Err(BeamError::InvalidSetting {
                            field: format!("{what}.table"),
                            value: *t,
                            reason: "times must strictly increase".into(),
                        });
                    }
                }
                Ok(())
            }
        }
    }
}

/// A concentrated load `F_n` at a node.
#[derive(Clone, Debug, PartialEq)]
pub struct PointLoad {
    /// Node index `0..=N`.
    pub node: usize,
    /// Frame of `value`.
    pub frame: LoadFrame,
    /// `[force, moment]` (6 components; planar beams use only 1, 3 | 2).
    pub value: Vector6<f64>,
    /// Time history.
    pub amplitude: Amplitude,
}

/// A uniformly distributed load `f1` (per unit length) over the whole beam.
#[derive(Clone, Debug, PartialEq)]
pub struct DistributedLoad {
    /// Frame of `value`.
    pub frame: LoadFrame,
    /// `[force, moment]` per unit length.
    pub value: Vector6<f64>,
    /// Time history.
    pub amplitude: Amplitude,
}

/// All loads on one beam. Fields may be updated in place between steps (e.g. by a controller).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Loads {
    /// Point loads.
    pub point: Vec<PointLoad>,
    /// Distributed loads.
    pub distributed: Vec<DistributedLoad>,
}

impl Loads {
    /// No loads.
    ///
    /// ```
    /// use intrinsic_beam::{LoadFrame, Loads};
    /// use nalgebra::Vector6;
    ///
    /// // a dead tip force along −e3 at node 4, and a follower distributed moment about e2
    /// let loads = Loads::none()
    ///     .with_point(4, LoadFrame::Dead, Vector6::new(0.0, 0.0, -1.0, 0.0, 0.0, 0.0))
    ///     .with_distributed(LoadFrame::Follower, Vector6::new(0.0, 0.0, 0.0, 0.0, 0.1, 0.0));
    /// assert_eq!(loads.point.len(), 1);
    /// ```
    pub fn none() -> Self {
        Self::default()
    }

    /// Adds a point load with constant amplitude.
    pub fn with_point(mut self, node: usize, frame: LoadFrame, value: Vector6<f64>) -> Self {
        self.point.push(PointLoad { node, frame, value, amplitude: Amplitude::Constant });
        self
    }

    /// Adds a distributed load with constant amplitude.
    pub fn with_distributed(mut self, frame: LoadFrame, value: Vector6<f64>) -> Self {
        self.distributed.push(DistributedLoad { frame, value, amplitude: Amplitude::Constant });
        self
    }

    /// Whether any load is a dead (global-frame) load.
    pub fn has_dead(&self) -> bool {
        self.point.iter().any(|p| p.frame == LoadFrame::Dead)
            || self.distributed.iter().any(|d| d.frame == LoadFrame::Dead)
    }

    /// Checks node indices, finiteness, amplitudes and (planar) in-plane components.
    pub fn validate(&self, components: Components, n_nodes: usize) -> Result<()> {
        for (i, p) in self.point.iter().enumerate() {
            let what = format!("point load {i}");
            if p.node >= n_nodes {
                return Err(BeamError::NodeOutOfRange { what, node: p.node, last: n_nodes - 1 });
            }
            for j in 0..6 {
                check_finite(&what, format!("component {j}"), p.value[j])?;
            }
            p.amplitude.validate(&what)?;
            components.check_vector(&what, &p.value)?;
        }
        for (i, d) in self.distributed.iter().enumerate() {
            let what = format!("distributed load {i}");
            for j in 0..6 {
                check_finite(&what, format!("component {j}"), d.value[j])?;
            }
            d.amplitude.validate(&what)?;
            components.check_vector(&what, &d.value)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn amplitudes() {
        assert_eq!(Amplitude::Ramp { duration: 2.0 }.at(1.0), 0.5);
        assert_eq!(Amplitude::Ramp { duration: 2.0 }.at(3.0), 1.0);
        let t = Amplitude::Table(vec![(0.0, 0.0), (1.0, 2.0), (2.0, 0.0)]);
        assert_eq!(t.at(0.5), 1.0);
        assert_eq!(t.at(1.5), 1.0);
        assert_eq!(t.at(5.0), 0.0);
        assert!(Amplitude::Ramp { duration: 0.0 }.validate("x").is_err());
        assert!(Amplitude::Table(vec![(1.0, 0.0), (0.5, 1.0)]).validate("x").is_err());
    }

    #[test]
    fn load_on_missing_node_is_an_error() {
        let loads = Loads::none().with_point(5, LoadFrame::Follower, Vector6::zeros());
        let err = loads.validate(Components::Spatial, 5).unwrap_err();
        assert!(matches!(err, BeamError::NodeOutOfRange { node: 5, last: 4, .. }), "{err}");
        let nan = Loads::none().with_distributed(LoadFrame::Dead, Vector6::repeat(f64::NAN));
        assert!(matches!(nan.validate(Components::Spatial, 3), Err(BeamError::NonFinite { .. })));
    }
}
