//! Settings of the shooting-interval integrators and the adaptive substep table.

use super::Integrator;
use crate::dynamics::Dynamics;
use crate::error::{invalid, Result};
use crate::la::norm_inf;
use nalgebra::DMatrix;

/// Largest residual contraction per iteration `‖r_{k+1}‖∞ / ‖r_k‖∞` the simplified Newton
/// iteration of the implicit midpoint rule accepts before it evaluates the Jacobian at the
/// current iterate and refactorises (an iteration with a fresh Jacobian is a full Newton
/// step, so the simplified iteration never evaluates more Jacobians than full Newton).
pub const SIMPLIFIED_NEWTON_MAX_RATE: f64 = 0.1;

/// Which one-step method runs inside a shooting interval. With the `serde` feature it reads
/// and writes as `rk4`, `implicit-midpoint`, `lawson-rk4`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
#[non_exhaustive]
pub enum IntegratorKind {
    /// Classical explicit Runge–Kutta of order 4.
    Rk4,
    /// Implicit midpoint rule (one-stage Gauss–Legendre, order 2), Newton inside.
    ImplicitMidpoint,
    /// Lawson exponential RK4 (order 4, exact on the linear part `L`).
    LawsonRk4,
}

/// The constant linear part `L` of the Lawson integrator.
#[derive(Clone, Debug, PartialEq)]
pub enum LinearPart {
    /// Take `L` from [`Dynamics::linear_part`] (error if the model has none).
    Model,
    /// A given `nx × nx` matrix, e.g. the Jacobian of `f` at a reference state.
    Matrix(DMatrix<f64>),
}

/// Settings of the shooting-interval integrator.
#[derive(Clone, Debug, PartialEq)]
pub struct IntegratorSettings {
    /// Method. Default [`IntegratorKind::Rk4`].
    pub kind: IntegratorKind,
    /// Substeps per shooting interval, `≥ 1`. Default 4.
    pub substeps: usize,
    /// Linear part for [`IntegratorKind::LawsonRk4`]. Default [`LinearPart::Model`].
    pub linear_part: LinearPart,
    /// Newton tolerance of the implicit midpoint rule on `‖r‖∞ / (1 + ‖m‖∞)`, in (0, 1e-2].
    /// Default 1e-13 (sensitivities are exact up to this residual).
    pub newton_tolerance: f64,
    /// Newton iteration limit, `≥ 1`. Default 30.
    pub newton_max_iterations: usize,
    /// Simplified Newton for the implicit midpoint rule: the iterations reuse the last
    /// factorised Newton matrix `I − h/2 ∂f/∂x` of the interval (the previous substep's, at its
    /// converged midpoint) and evaluate the Jacobian and refactorise only when the residual
    /// contracts slower than [`SIMPLIFIED_NEWTON_MAX_RATE`] per iteration (and after the first
    /// step with [`IntegratorSettings::refresh_after_first_step`]). The convergence test
    /// is the same as full Newton's, and the sensitivities stay exact (Jacobian and factor at
    /// the converged midpoint). `false`: full Newton (a Jacobian and a factorisation per
    /// iteration). Default `true`.
    pub simplified_newton: bool,
    /// Simplified Newton: the iterate after the first step (taken with the previous
    /// substep's factor, or the warm start's) evaluates the Jacobian with its residual
    /// (one [`Dynamics::rhs_and_jacobians`] call) and refactorises there, so the iteration
    /// continues from a factor near the midpoint. Pays when the model's Jacobian evaluation
    /// costs a few right-hand sides and includes one (measured on the exact-joints model of
    /// the 3D NMPC, `h ω` up to 23: about 10 % fewer evaluation costs per sample); `false`: the
    /// factor is refreshed only when the contraction is slower than
    /// [`SIMPLIFIED_NEWTON_MAX_RATE`], which is cheaper when Jacobians are expensive.
    /// Default `true`.
    pub refresh_after_first_step: bool,
    /// State-adapted substep counts (explicit methods): each shooting interval's count is
    /// chosen from its nodes and control by an error table, fixed during one SQP iteration.
    /// `None` (default): every interval uses `substeps`.
    pub adaptive: Option<AdaptiveSubsteps>,
    /// Fewer substeps at the far end of the horizon: the shooting intervals from
    /// [`TailSubsteps::from_interval`] on use [`TailSubsteps::substeps`] instead of
    /// `substeps`. Only the first control of a plan is applied; the tail's coarser steps
    /// keep its slow motion to second order (implicit midpoint) and, with an A-stable method,
    /// its fast modes bounded, at a fraction of the tail's cost (docs/ocp-transcription.md,
    /// "Coarser substeps at the end of the horizon"). Not with `adaptive`. `None` (default):
    /// every interval uses `substeps`.
    pub tail: Option<TailSubsteps>,
}

/// The substep count of the horizon's last shooting intervals ([`IntegratorSettings::tail`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TailSubsteps {
    /// Index of the first interval of the tail, `≥ 1` and below the problem's interval
    /// count.
    pub from_interval: usize,
    /// Substeps of each tail interval, `≥ 1`.
    pub substeps: usize,
}

/// An a priori one-interval error table for choosing substep counts from the state.
///
/// Model (explicit methods of order 4):
/// `err(n) ≈ (Δt/n)⁴ (c_x ρ_x² + c_u ρ_u + c_l ρ_l²)` with `ρ_x = ‖∂f/∂x(x, u) − L‖∞` (the
/// part of the Jacobian the method does not integrate exactly; `L = 0` for RK4), `ρ_u =
/// ‖∂f/∂u(x, u) u‖∞` (the forcing, which excites the fast modes of `L`) and `ρ_l = ‖Lx‖∞`
/// (motion in the fast modes), `ρ_x` and `ρ_l` at the interval's start node, maximised
/// with the end node when it is known. On the ROM-structured sample each part was measured
/// to grow like its term and like `n⁻⁴` (docs/ocp-transcription.md); the constants are
/// fitted per model by [`AdaptiveSubsteps::calibrate`]. The count is the smallest
/// `n ∈ [min_substeps, max_substeps]` with `err(n) ≤ tolerance`.
#[derive(Clone, Debug, PartialEq)]
pub struct AdaptiveSubsteps {
    /// Target one-interval error (the error measure of the calibration: max norm relative to
    /// `max(‖x⁺‖∞, 1)`), in (0, 1). Default 1e-3.
    pub tolerance: f64,
    /// `c_x ≥ 0`. Default 15 (the Lawson RK4 fit on `ModalLike::paper_sized_rom`).
    pub state_constant: f64,
    /// `c_u ≥ 0`. Default 5000 (same fit).
    pub input_constant: f64,
    /// `c_l ≥ 0`. Default 64 (same fit).
    pub fast_constant: f64,
    /// Smallest count, `≥ 1`. Default 8 (below it the error leaves the `n⁻⁴` regime when
    /// `Δt ω_max` is large).
    pub min_substeps: usize,
    /// Largest count, `≥ min_substeps`, at most 1024 (one propagator per count is precomputed).
    /// Default 48.
    pub max_substeps: usize,
}

impl Default for AdaptiveSubsteps {
    fn default() -> Self {
        Self {
            tolerance: 1e-3,
            state_constant: 15.0,
            input_constant: 5000.0,
            fast_constant: 64.0,
            min_substeps: 8,
            max_substeps: 48,
        }
    }
}

/// The one-interval error measure of the calibration: `‖x − x_ref‖∞ / max(‖x_ref‖∞, 1)`.
pub fn interval_error(x: &[f64], x_ref: &[f64]) -> f64 {
    let d = x.iter().zip(x_ref).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    d / norm_inf(x_ref).max(1.0)
}

impl AdaptiveSubsteps {
    /// Checks the ranges documented on each field.
    pub fn validate(&self) -> Result<()> {
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(invalid("adaptive.tolerance", self.tolerance, "must be in (0, 1)"));
        }
        for (name, v) in [
            ("adaptive.state_constant", self.state_constant),
            ("adaptive.input_constant", self.input_constant),
            ("adaptive.fast_constant", self.fast_constant),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(invalid(name, v, "must be finite and ≥ 0"));
            }
        }
        if self.min_substeps == 0 {
            return Err(invalid("adaptive.min_substeps", self.min_substeps, "must be at least 1"));
        }
        if self.max_substeps < self.min_substeps || self.max_substeps > 1024 {
            return Err(invalid(
                "adaptive.max_substeps",
                self.max_substeps,
                "must be in [min_substeps, 1024]",
            ));
        }
        Ok(())
    }

    /// Predicted one-interval error with `n` substeps over `interval` for the indicators
    /// `rho = (ρ_x, ρ_u, ρ_l)`.
    pub fn predicted_error(&self, interval: f64, n: usize, rho: (f64, f64, f64)) -> f64 {
        let (x, u, l) = rho;
        (interval / n as f64).powi(4)
            * (self.state_constant * x * x + self.input_constant * u + self.fast_constant * l * l)
    }

    /// The smallest count in `[min_substeps, max_substeps]` whose predicted error meets the
    /// tolerance (`max_substeps` when none does, or when an indicator is not finite).
    pub fn substeps_for(&self, interval: f64, rho: (f64, f64, f64)) -> usize {
        if !(rho.0.is_finite() && rho.1.is_finite() && rho.2.is_finite()) {
            return self.max_substeps;
        }
        // err(n) = C n⁻⁴ ≤ tol  ⇔  n ≥ (C / tol)^{1/4}
        let c = self.predicted_error(interval, 1, rho);
        let n = (c / self.tolerance).powf(0.25).ceil();
        if n.is_nan() || n > self.max_substeps as f64 {
            return self.max_substeps;
        }
        let mut n = (n as usize).max(self.min_substeps);
        // guard the rounding of the fourth root
        while n < self.max_substeps && self.predicted_error(interval, n, rho) > self.tolerance {
            n += 1;
        }
        n
    }

    /// Fits the three constants for `model` and the method of `settings` (its `adaptive`
    /// field is ignored) from sample points `(x, u)`: the one-interval errors against a
    /// reference with `reference_substeps` substeps are measured at the counts
    /// `probe_substeps`, and among the ratios `c_u / c_x`, `c_l / c_x` on logarithmic grids
    /// (10⁻³ … 10⁶) the tightest model that over-predicts *every* measured error is kept
    /// (smallest total log over-prediction). Errors below 1e-12 are ignored (round-off).
    /// `tolerance`, `min_substeps`, `max_substeps` are copied into the result.
    #[allow(clippy::too_many_arguments)]
    pub fn calibrate<D: Dynamics + ?Sized>(
        model: &D,
        settings: &IntegratorSettings,
        interval: f64,
        samples: &[(Vec<f64>, Vec<f64>)],
        probe_substeps: &[usize],
        reference_substeps: usize,
        tolerance: f64,
        min_substeps: usize,
        max_substeps: usize,
    ) -> Result<Self> {
        if samples.is_empty() {
            return Err(invalid("samples", 0, "need at least one calibration sample"));
        }
        if probe_substeps.is_empty() {
            return Err(invalid("probe_substeps", 0, "need at least one probe count"));
        }
        let base = IntegratorSettings { adaptive: None, ..settings.clone() };
        let mut reference = Integrator::new(
            model,
            &IntegratorSettings { substeps: reference_substeps, ..base.clone() },
            interval,
        )?;
        let mut probes = probe_substeps
            .iter()
            .map(|&n| {
                Integrator::new(
                    model,
                    &IntegratorSettings { substeps: n, ..base.clone() },
                    interval,
                )
            })
            .collect::<Result<Vec<_>>>()?;
        // (h⁴-scaled) measurements: err / (Δt/n)⁴ = c_x a + c_u b + c_l c
        let mut data: Vec<(f64, f64, f64, f64)> = Vec::new();
        let nx = model.nx();
        let (mut xr, mut xe) = (vec![0.0; nx], vec![0.0; nx]);
        for (x, u) in samples {
            reference.integrate(model, x, u, &mut xr)?;
            let (a, b, c) = reference.indicators(model, x, u, Some(&xr));
            for (int, &n) in probes.iter_mut().zip(probe_substeps) {
                int.integrate(model, x, u, &mut xe)?;
                let e = interval_error(&xe, &xr);
                if e > 1e-12 {
                    data.push((e / (interval / n as f64).powi(4), a * a, b, c * c));
                }
            }
        }
        let mut best: Option<(f64, f64, f64, f64)> = None;
        let grid = |k: i32| if k < 0 { 0.0 } else { 10f64.powf(0.25 * k as f64 - 3.0) };
        for ku in -1..=36 {
            for kl in -1..=36 {
                let (bu, bl) = (grid(ku), grid(kl));
                let model_of = |a: f64, b: f64, c: f64| a + bu * b + bl * c;
                let scale =
                    data.iter().map(|&(y, a, b, c)| y / model_of(a, b, c)).fold(0.0, f64::max);
                if !scale.is_finite() || scale == 0.0 {
                    continue;
                }
                let over: f64 =
                    data.iter().map(|&(y, a, b, c)| (scale * model_of(a, b, c) / y).ln()).sum();
                if best.is_none_or(|(o, ..)| over < o) {
                    best = Some((over, scale, scale * bu, scale * bl));
                }
            }
        }
        let Some((_, cx, cu, cl)) = best else {
            return Err(invalid(
                "samples",
                "no error above 1e-12 or no finite fit",
                "calibration needs samples whose errors the model can explain",
            ));
        };
        let out = Self {
            tolerance,
            state_constant: cx,
            input_constant: cu,
            fast_constant: cl,
            min_substeps,
            max_substeps,
        };
        out.validate()?;
        Ok(out)
    }
}

impl Default for IntegratorSettings {
    fn default() -> Self {
        Self {
            kind: IntegratorKind::Rk4,
            substeps: 4,
            linear_part: LinearPart::Model,
            newton_tolerance: 1e-13,
            newton_max_iterations: 30,
            simplified_newton: true,
            refresh_after_first_step: true,
            adaptive: None,
            tail: None,
        }
    }
}

impl IntegratorSettings {
    /// Settings for `kind` with `substeps` substeps, other fields default.
    pub fn new(kind: IntegratorKind, substeps: usize) -> Self {
        Self { kind, substeps, ..Self::default() }
    }

    /// Checks the ranges documented on each field.
    pub fn validate(&self) -> Result<()> {
        if self.substeps == 0 {
            return Err(invalid("integrator.substeps", self.substeps, "must be at least 1"));
        }
        if !(self.newton_tolerance > 0.0 && self.newton_tolerance <= 1e-2) {
            return Err(invalid(
                "integrator.newton_tolerance",
                self.newton_tolerance,
                "must be in (0, 1e-2]",
            ));
        }
        if self.newton_max_iterations == 0 {
            return Err(invalid(
                "integrator.newton_max_iterations",
                self.newton_max_iterations,
                "must be at least 1",
            ));
        }
        if let Some(a) = &self.adaptive {
            a.validate()?;
            if self.kind == IntegratorKind::ImplicitMidpoint {
                return Err(invalid(
                    "integrator.adaptive",
                    "ImplicitMidpoint",
                    "state-adapted substeps need an explicit method (RK4, LawsonRk4)",
                ));
            }
            if self.substeps < a.min_substeps || self.substeps > a.max_substeps {
                return Err(invalid(
                    "integrator.substeps",
                    self.substeps,
                    "must lie in [adaptive.min_substeps, adaptive.max_substeps]",
                ));
            }
        }
        if let Some(t) = &self.tail {
            if self.adaptive.is_some() {
                return Err(invalid(
                    "integrator.tail",
                    format!("{t:?}"),
                    "cannot be combined with adaptive substeps (they choose every interval's count)",
                ));
            }
            if t.substeps == 0 {
                return Err(invalid("integrator.tail.substeps", t.substeps, "must be at least 1"));
            }
            if t.from_interval == 0 {
                return Err(invalid(
                    "integrator.tail.from_interval",
                    t.from_interval,
                    "must be at least 1 (from 0 the tail is every interval: set `substeps`)",
                ));
            }
        }
        Ok(())
    }

    /// The substep count of shooting interval `k` without adaptation: the tail's from
    /// [`TailSubsteps::from_interval`] on, else `substeps`.
    pub fn substeps_of(&self, k: usize) -> usize {
        match &self.tail {
            Some(t) if k >= t.from_interval => t.substeps,
            _ => self.substeps,
        }
    }

    /// The substep counts an integrator built from these settings can run:
    /// `[min_substeps, max_substeps]` when adaptive, else `substeps` and the tail's.
    pub(super) fn count_range(&self) -> (usize, usize) {
        match (&self.adaptive, &self.tail) {
            (Some(a), _) => (a.min_substeps, a.max_substeps),
            (None, Some(t)) => (self.substeps.min(t.substeps), self.substeps.max(t.substeps)),
            (None, None) => (self.substeps, self.substeps),
        }
    }
}
