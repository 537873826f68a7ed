//! How a solve ended, its counters and its iteration log.

/// How a solve ended. Only [`SqpStatus::Solved`], [`SqpStatus::MaxIterations`] and
/// [`SqpStatus::RealTimeIteration`] leave a new iterate; after the others the iterate is
/// the last accepted one (see [`SqpStatus::has_iterate`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum SqpStatus {
    /// No solve yet.
    Unsolved,
    /// KKT residual below the tolerance.
    Solved,
    /// Iteration limit reached (the iterate is the last one).
    MaxIterations,
    /// One real-time iteration done
    /// ([`SqpMode::RealTimeIteration`](crate::SqpMode::RealTimeIteration)).
    RealTimeIteration,
    /// The QP subproblem is primal infeasible (e.g. inconsistent state bounds).
    QpInfeasible,
    /// The QP solver failed (numerical error, iteration limit, indefinite Hessian).
    QpFailed,
    /// The dynamics or its derivatives returned NaN/∞ at an iterate.
    NonFiniteDynamics,
    /// The implicit integrator's Newton iteration failed or its matrix was singular.
    IntegratorFailed,
    /// The merit line search reached its minimum step.
    LineSearchFailed,
}

impl SqpStatus {
    /// Whether the solver's iterate is the product of this solve's iterations (as opposed to a
    /// failure that stopped it early; the iterate is then still the last accepted one).
    pub fn has_iterate(self) -> bool {
        matches!(self, SqpStatus::Solved | SqpStatus::MaxIterations | SqpStatus::RealTimeIteration)
    }
}

/// Counters and timings of one solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SqpStats {
    /// How it ended.
    pub status: SqpStatus,
    /// SQP iterations (QPs solved and steps taken).
    pub iterations: usize,
    /// Total QP solver iterations.
    pub qp_iterations: usize,
    /// Interval integrations (with or without sensitivities, line-search trials included).
    pub integrator_calls: usize,
    /// Model evaluations and Newton-matrix factorisations in those integrations.
    pub evaluations: crate::Evaluations,
    /// Hessian regularisations (exact Hessian only).
    pub regularisations: usize,
    /// Iterations of [`HessianApproximation::GaussNewtonThenExact`](crate::HessianApproximation::GaussNewtonThenExact)
    /// after the switch whose exact reduced Hessian was indefinite, so the QP took the
    /// Gauss–Newton Hessian.
    pub gauss_newton_fallbacks: usize,
    /// Second-order corrections accepted by the line search.
    pub second_order_corrections: usize,
    /// QPs solved again with a Levenberg–Marquardt term after a failure
    /// ([`crate::SqpSettings::qp_recovery`]).
    pub qp_recoveries: usize,
    /// Quasi-Newton block updates (SR1 or damped BFGS) made in this solve
    /// ([`HessianApproximation::GaussNewtonThenQuasiNewton`](crate::HessianApproximation::GaussNewtonThenQuasiNewton)).
    pub quasi_newton_updates: usize,
    /// Final KKT residual (max norm).
    pub kkt: f64,
    /// Final cost `J`.
    pub cost: f64,
    /// Final constraint violation (defects, initial condition, state bounds; max norm).
    pub constraint_violation: f64,
    /// Seconds in the integrators (linearisation, exact Hessians, line-search trials).
    pub time_integration: f64,
    /// Seconds building Hessians, condensing and expanding.
    pub time_condensing: f64,
    /// Seconds in the QP solver.
    pub time_qp: f64,
    /// Total seconds.
    pub time_total: f64,
    /// Mean substeps per interval of the last linearisation (the fixed count unless
    /// [`IntegratorSettings::adaptive`](crate::IntegratorSettings::adaptive) is set).
    pub mean_substeps: f64,
}

impl Default for SqpStats {
    fn default() -> Self {
        Self {
            status: SqpStatus::Unsolved,
            iterations: 0,
            qp_iterations: 0,
            integrator_calls: 0,
            evaluations: crate::Evaluations::default(),
            regularisations: 0,
            gauss_newton_fallbacks: 0,
            second_order_corrections: 0,
            qp_recoveries: 0,
            quasi_newton_updates: 0,
            kkt: f64::NAN,
            cost: f64::NAN,
            constraint_violation: f64::NAN,
            time_integration: 0.0,
            time_condensing: 0.0,
            time_qp: 0.0,
            time_total: 0.0,
            mean_substeps: f64::NAN,
        }
    }
}

impl SqpStats {
    /// Whether this solve's result is preferable to `other`'s for the same problem: a
    /// [`SqpStatus::Solved`] result over any other; among two solved, the lower cost (two local
    /// minima); among two unsolved, the lower KKT residual (NaN last).
    pub fn better_than(&self, other: &SqpStats) -> bool {
        let (a, b) = (self.status == SqpStatus::Solved, other.status == SqpStatus::Solved);
        match (a, b) {
            (true, false) => true,
            (false, true) => false,
            (true, true) => self.cost < other.cost,
            (false, false) => self.kkt < other.kkt || (other.kkt.is_nan() && !self.kkt.is_nan()),
        }
    }
}

/// One line of the iteration log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationLog {
    /// Iteration index (0 = first linearisation).
    pub iteration: usize,
    /// Cost at the iterate.
    pub cost: f64,
    /// KKT residual at the iterate (with the multipliers of the previous QP).
    pub kkt: f64,
    /// Constraint violation at the iterate.
    pub constraint_violation: f64,
    /// Max norm of the QP step `Δw`.
    pub step_norm: f64,
    /// Step length taken.
    pub step_length: f64,
    /// QP iterations.
    pub qp_iterations: usize,
}
