//! SQP settings: mode, Hessian, QP form, globalisation, tolerances.

use crate::error::{invalid, Result};
use crate::integrator::IntegratorSettings;
use crate::qp::QpForm;

/// [`QpForm::Auto`] switches to the sparse multiple-shooting QP when the Cholesky-based
/// condition estimate of the condensed Hessian exceeds this (a condensed solve would keep
/// fewer than ~6 digits of the step).
pub const AUTO_SPARSE_CONDITION: f64 = 1e10;

/// Hessian of the QP subproblems.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum HessianApproximation {
    /// Gauss–Newton: the cost Hessian (exact for the quadratic cost (34), no integrator work).
    GaussNewton,
    /// Exact Hessian of the Lagrangian (adds `∇²(λᵀΦ)` from the integrators; needs
    /// [`Dynamics::weighted_hessian`](crate::Dynamics::weighted_hessian), an explicit
    /// integrator and a condensed QP form).
    /// Indefinite condensed Hessians are regularised by `δI` until a Cholesky succeeds.
    Exact,
    /// Exact Hessian of the Lagrangian with every stage block projected onto the positive
    /// definite matrices before the QP (acados' `PROJECT`): the block
    /// `H_k = ∇²_{(s,u)}(ℓ_k + λ_{k+1}ᵀΦ_k)` is eigen-decomposed, `H_k = VΛVᵀ`, and replaced by
    /// `V max(Λ, ε_k) Vᵀ` with `ε_k = PROJECTION_FLOOR · max(1, max|Λ|)` (see
    /// [`PROJECTION_FLOOR`]). The QP is then convex in every form (the sparse form too), the
    /// step a descent direction of the merit, and near a solution with positive definite blocks
    /// the projection is inactive (superlinear convergence). Needs what [`Self::Exact`] needs
    /// except the condensed form.
    ExactProjected,
    /// Gauss–Newton until the KKT residual of an iterate is at most `switch_kkt`, then
    /// [`Self::Exact`] for the rest of the solve. Gauss–Newton steps are descent directions of
    /// the merit far from a solution (its Hessian is positive definite) and lead into the basin
    /// of the lower minimum on the paper problems; near the solution Gauss–Newton converges
    /// only linearly (it omits `λᵀ∇²Φ`), and the merit line search can stall on its steps,
    /// while the exact Hessian converges superlinearly. Needs what [`Self::Exact`] needs.
    GaussNewtonThenExact {
        /// KKT residual (max norm) at or below which the exact Hessian is used, in `(0, ∞)`.
        switch_kkt: f64,
    },
    /// Gauss–Newton until the KKT residual of an iterate is at most `switch_kkt`, then the
    /// Gauss–Newton blocks plus a structured quasi-Newton estimate `M_k` of the dynamics'
    /// curvature `∇²_{(s,u)}(λ_{k+1}ᵀΦ_k)`, one `(nx+nu)²` block per interval, for the rest of
    /// the solve: what [`Self::GaussNewtonThenExact`] does where the model or the integrator
    /// has no second derivatives (the implicit midpoint rule, models without
    /// [`Dynamics::weighted_hessian`](crate::Dynamics::weighted_hessian)). `M_k` starts at 0
    /// at every solve and is updated from the first accepted step on (the Gauss–Newton phase
    /// collects curvature too) by the symmetric rank-one formula (Nocedal & Wright, 2nd ed.,
    /// (6.24)) with `s_k = z_k⁺ − z_k`, `z_k = (s_k, u_k)`, and
    /// `y_k = ([A_k B_k]⁺ − [A_k B_k])ᵀ λ_{k+1}⁺` (the change of `∇_z(λᵀΦ_k)` at the new
    /// multipliers; the cost is quadratic, its curvature is exact in the Gauss–Newton part):
    /// `M_k ← M_k + r rᵀ / (rᵀs)`, `r = y − M_k s`, skipped when `|rᵀs| < 1e-8‖r‖‖s‖`
    /// (N&W (6.26)). SR1 rather than BFGS because the true blocks are indefinite (only the
    /// reduced Hessian is definite at a solution); the indefinite QP is then treated as the
    /// exact one (inertia correction, Levenberg–Marquardt retries). The derivatives are
    /// first-order only (no adjoint sweeps), so an iteration costs what a Gauss–Newton one
    /// does plus `O(N (nx+nu)²)`.
    ///
    /// With `damped_bfgs` the whole block `B_k = G_k + M_k` (`G_k` its Gauss–Newton part) is
    /// updated instead by Powell's damped BFGS formula (N&W Procedure 18.2; the block-wise
    /// update of multiple-shooting SQP, Bock & Plitt 1984) with `y_k` plus the exact cost
    /// curvature `G_k s_k`: `r = θy + (1 − θ)B s`, `θ = 1` if `sᵀy ≥ 0.2 sᵀBs`, else
    /// `0.8 sᵀBs / (sᵀBs − sᵀy)`; `B ← B − B s sᵀB / sᵀBs + r rᵀ / sᵀr`. Every block stays
    /// positive definite (a convex QP without inertia correction, at the price of a model that
    /// cannot carry the blocks' negative curvature).
    GaussNewtonThenQuasiNewton {
        /// KKT residual (max norm) at or below which `M_k` enters the QP, in `(0, ∞)`.
        switch_kkt: f64,
        /// Damped BFGS on the whole blocks (`true`) or SR1 on the curvature (`false`).
        damped_bfgs: bool,
    },
}

/// KKT residual at which [`SqpSettings::converge`] switches from the Gauss–Newton to the
/// exact Hessian.
pub const CONVERGE_SWITCH_KKT: f64 = 1e-2;

/// Relative eigenvalue floor of [`HessianApproximation::ExactProjected`]: the stage blocks'
/// eigenvalues are clipped to at least `PROJECTION_FLOOR · max(1, max |λᵢ|)`.
pub const PROJECTION_FLOOR: f64 = 1e-4;

impl HessianApproximation {
    /// Whether the Hessian includes (or may switch to) the dynamics' curvature `λᵀ∇²Φ`
    /// (integrator adjoint sweeps).
    pub fn is_exact(self) -> bool {
        !matches!(
            self,
            HessianApproximation::GaussNewton
                | HessianApproximation::GaussNewtonThenQuasiNewton { .. }
        )
    }

    /// Whether the QP may take curvature beyond the Gauss–Newton blocks that makes its
    /// blocks indefinite after a switch (the hybrids).
    pub(crate) fn is_hybrid(self) -> bool {
        matches!(
            self,
            HessianApproximation::GaussNewtonThenExact { .. }
                | HessianApproximation::GaussNewtonThenQuasiNewton { .. }
        )
    }

    /// The switch of a hybrid (`None` otherwise).
    pub(crate) fn switch_kkt(self) -> Option<f64> {
        match self {
            HessianApproximation::GaussNewtonThenExact { switch_kkt }
            | HessianApproximation::GaussNewtonThenQuasiNewton { switch_kkt, .. } => {
                Some(switch_kkt)
            }
            _ => None,
        }
    }
}

/// Globalisation of the SQP step `w ← w + t Δw`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Globalisation {
    /// `t = 1`.
    FullStep,
    /// The paper's fixed sub-relaxation `t = alpha ∈ (0, 1]`.
    FixedRelaxation {
        /// Relaxation factor.
        alpha: f64,
    },
    /// Backtracking on the ℓ1 merit `φ(w) = J + ν (Σ‖d_k‖₁ + ‖x0 − s_0‖₁ + state-bound
    /// violations)` with the Armijo condition `φ(w + tΔw) ≤ φ(w) + armijo·t·Dφ(w; Δw)`,
    /// `Dφ = ∇JᵀΔw − ν c(w)` (Nocedal & Wright, *Numerical Optimization*, 2nd ed., §18.3).
    /// A trial integrates the intervals without sensitivities (states and cost only).
    MeritLineSearch {
        /// Armijo constant in (0, 0.5). Typical 1e-4.
        armijo: f64,
        /// Backtracking factor in (0, 1). Typical 0.5.
        backtracking: f64,
        /// Smallest step before giving up (status
        /// [`SqpStatus::LineSearchFailed`](crate::SqpStatus::LineSearchFailed)), in (0, 1).
        min_step: f64,
        /// Penalty rule. `false`: `ν` only grows (`ν ← 2‖λ‖∞` whenever `ν < 1.1‖λ‖∞`) and is
        /// kept across solves. `true`: `ν` follows the QP multipliers both ways, Powell's rule
        /// `ν ← max(ν̄, ½(ν + ν̄))` with `ν̄ = 1.1‖(λ, μ)‖∞` (N&W (18.36)), reset at every solve;
        /// a penalty inflated by early large multipliers otherwise makes the merit see mostly
        /// the defects and reject steps along the curved constraint manifold.
        adaptive_penalty: bool,
        /// Second-order correction (N&W §18.3, (18.24)): when the full step fails the Armijo
        /// test, the QP is solved again with the defects `d_k + d_k(w + Δw)` (same Hessian and
        /// Jacobians; a correction of the step against the constraints' curvature, which
        /// otherwise rejects full steps near the solution — the Maratos effect) and the
        /// corrected full step is tried before backtracking.
        second_order_correction: bool,
    },
    /// Filter line search on (cost, ℓ1 constraint violation) with the second-order
    /// correction (the globalisation of IPOPT; see the `filter` module). A trial integrates
    /// the intervals without sensitivities.
    Filter {
        /// Backtracking factor in (0, 1). Typical 0.5.
        backtracking: f64,
        /// Smallest step before giving up (status
        /// [`SqpStatus::LineSearchFailed`](crate::SqpStatus::LineSearchFailed)), in (0, 1).
        min_step: f64,
        /// Try the second-order correction when the full step is rejected with a larger
        /// violation.
        second_order_correction: bool,
    },
}

impl Globalisation {
    /// Filter line search, `backtracking = 0.5`, `min_step = 1e-8`, second-order correction.
    pub fn filter() -> Self {
        Globalisation::Filter { backtracking: 0.5, min_step: 1e-8, second_order_correction: true }
    }

    /// Merit line search with `armijo = 1e-4`, `backtracking = 0.5`, `min_step = 1e-6`, the
    /// growing penalty, no second-order correction (what the closed loops use).
    pub fn merit() -> Self {
        Globalisation::MeritLineSearch {
            armijo: 1e-4,
            backtracking: 0.5,
            min_step: 1e-6,
            adaptive_penalty: false,
            second_order_correction: false,
        }
    }

    /// Merit line search with the penalty following the multipliers and the second-order
    /// correction (`armijo = 1e-4`, `backtracking = 0.5`, `min_step = 1e-8`): what
    /// [`SqpSettings::converge`] uses.
    pub fn merit_soc() -> Self {
        Globalisation::MeritLineSearch {
            armijo: 1e-4,
            backtracking: 0.5,
            min_step: 1e-8,
            adaptive_penalty: true,
            second_order_correction: true,
        }
    }
}

/// What one call of [`SqpSolver::solve`](crate::SqpSolver::solve) does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum SqpMode {
    /// Iterate to the KKT tolerance or the iteration limit.
    Sqp,
    /// Real-time iteration: exactly one linearisation, QP and step per call. With the
    /// implicit midpoint rule, the line-search trials warm-start their Newton iterations from
    /// the linearisation's converged substeps
    /// ([`Integrator::integrate_near`](crate::Integrator::integrate_near)).
    RealTimeIteration,
    /// Linear–quadratic (linear MPC): the dynamics are linearised once at the reference
    /// `(x_r, u_r)` (`Φ(x, u) ≈ Φ(x_r, u_r) + A(x − x_r) + B(u − u_r)`); each call solves
    /// that QP (one QP per sample).
    LinearQuadratic,
}

/// SQP settings. Defaults in parentheses.
#[derive(Clone, Debug, PartialEq)]
pub struct SqpSettings {
    /// Mode (default `SqpMode::Sqp`).
    pub mode: SqpMode,
    /// Hessian (default `HessianApproximation::GaussNewton`).
    pub hessian: HessianApproximation,
    /// QP form (default `QpForm::Auto`).
    pub qp_form: QpForm,
    /// Globalisation (default: [merit line search](Globalisation::merit)).
    pub globalisation: Globalisation,
    /// Levenberg–Marquardt term `μ ≥ 0` added to every Hessian block (default 0).
    pub levenberg_marquardt: f64,
    /// SQP iteration limit ≥ 1 (default 50).
    pub max_iterations: usize,
    /// Termination: max-norm KKT residual (natural residual of stationarity with the bound
    /// projections, defects, initial condition, state-bound violation) (default 1e-8).
    pub kkt_tolerance: f64,
    /// QP solver tolerance (Clarabel gap/feasibility, dense IP residual and μ) (default 1e-11).
    pub qp_tolerance: f64,
    /// QP iteration limit (default 200).
    pub qp_max_iterations: usize,
    /// Integrator inside the shooting intervals (default RK4, 4 substeps).
    pub integrator: IntegratorSettings,
    /// Recovery from a failed QP (numerical failure or iteration limit, not infeasibility):
    /// solve it again with a Levenberg–Marquardt term `μI` added to the Hessian blocks,
    /// `μ = 10⁻⁵…10¹ × (1 + max diagonal entry)` growing tenfold per attempt (a shorter,
    /// better conditioned step); the status is
    /// [`SqpStatus::QpFailed`](crate::SqpStatus::QpFailed) only when every attempt fails
    /// (default false).
    pub qp_recovery: bool,
    /// Integrate the shooting intervals of a linearisation and of the line-search trials on
    /// the rayon thread pool (Gauss–Newton path; exact-Hessian sweeps stay sequential); every
    /// sum runs in interval order, so the iterates are the same to the bit for any thread
    /// count (default false).
    pub parallel_intervals: bool,
}

impl Default for SqpSettings {
    fn default() -> Self {
        Self {
            mode: SqpMode::Sqp,
            hessian: HessianApproximation::GaussNewton,
            qp_form: QpForm::Auto,
            globalisation: Globalisation::merit(),
            levenberg_marquardt: 0.0,
            max_iterations: 50,
            kkt_tolerance: 1e-8,
            qp_tolerance: 1e-11,
            qp_max_iterations: 200,
            integrator: IntegratorSettings::default(),
            parallel_intervals: false,
            qp_recovery: false,
        }
    }
}

impl SqpSettings {
    /// A full SQP to the KKT tolerance 1e-8 (at most 60 iterations) with the
    /// [second-order-corrected merit line search](Globalisation::merit_soc), QP recovery, the
    /// Hessian [`HessianApproximation::GaussNewtonThenExact`] switching at
    /// [`CONVERGE_SWITCH_KKT`] and `integrator` with its implicit-midpoint Newton tolerance at
    /// most the default 1e-13 (a real-time loop may stop its Newton iterations earlier; a KKT
    /// residual of 1e-8 needs interval maps exact to round-off): the settings that solve one
    /// problem to convergence, whatever a real-time loop uses.
    pub fn converge(integrator: IntegratorSettings) -> Self {
        let newton_tolerance =
            integrator.newton_tolerance.min(IntegratorSettings::default().newton_tolerance);
        let integrator = IntegratorSettings { newton_tolerance, ..integrator };
        Self {
            mode: SqpMode::Sqp,
            hessian: HessianApproximation::GaussNewtonThenExact { switch_kkt: CONVERGE_SWITCH_KKT },
            globalisation: Globalisation::merit_soc(),
            max_iterations: 60,
            kkt_tolerance: 1e-8,
            qp_recovery: true,
            integrator,
            ..Self::default()
        }
    }

    /// [`SqpSettings::converge`] with the [filter line search](Globalisation::filter) instead of
    /// the merit: the second start of `flexmpc ocp --converge` (each converges on paper
    /// problems where the other does not, measured in `docs/ocp-transcription.md`).
    pub fn converge_filter(integrator: IntegratorSettings) -> Self {
        Self { globalisation: Globalisation::filter(), ..Self::converge(integrator) }
    }

    /// [`SqpSettings::converge`] with [`HessianApproximation::GaussNewtonThenQuasiNewton`]
    /// (switching at [`CONVERGE_SWITCH_KKT`]): for models or integrators without second
    /// derivatives.
    pub fn converge_quasi_newton(integrator: IntegratorSettings) -> Self {
        Self {
            hessian: HessianApproximation::GaussNewtonThenQuasiNewton {
                switch_kkt: CONVERGE_SWITCH_KKT,
                damped_bfgs: false,
            },
            ..Self::converge(integrator)
        }
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<()> {
        self.integrator.validate()?;
        if !(self.levenberg_marquardt >= 0.0 && self.levenberg_marquardt.is_finite()) {
            return Err(invalid(
                "levenberg_marquardt",
                self.levenberg_marquardt,
                "must be finite and ≥ 0",
            ));
        }
        if self.max_iterations == 0 {
            return Err(invalid("max_iterations", self.max_iterations, "must be at least 1"));
        }
        if self.kkt_tolerance.is_nan() || self.kkt_tolerance <= 0.0 {
            return Err(invalid("kkt_tolerance", self.kkt_tolerance, "must be positive"));
        }
        if !(self.qp_tolerance > 0.0 && self.qp_tolerance < 1e-2) {
            return Err(invalid("qp_tolerance", self.qp_tolerance, "must be in (0, 1e-2)"));
        }
        if self.qp_max_iterations == 0 {
            return Err(invalid("qp_max_iterations", self.qp_max_iterations, "must be at least 1"));
        }
        if let Some(switch_kkt) = self.hessian.switch_kkt() {
            if switch_kkt.is_nan() || switch_kkt <= 0.0 {
                return Err(invalid("hessian.switch_kkt", switch_kkt, "must be positive"));
            }
        }
        match self.globalisation {
            Globalisation::FullStep => {}
            Globalisation::FixedRelaxation { alpha } => {
                if !(alpha > 0.0 && alpha <= 1.0) {
                    return Err(invalid("globalisation.alpha", alpha, "must be in (0, 1]"));
                }
            }
            Globalisation::Filter { backtracking, min_step, .. } => {
                validate_backtracking(backtracking, min_step)?;
            }
            Globalisation::MeritLineSearch { armijo, backtracking, min_step, .. } => {
                if !(armijo > 0.0 && armijo < 0.5) {
                    return Err(invalid("globalisation.armijo", armijo, "must be in (0, 0.5)"));
                }
                validate_backtracking(backtracking, min_step)?;
            }
        }
        Ok(())
    }
}

/// The backtracking factor and the smallest step of a line search, each in (0, 1).
fn validate_backtracking(backtracking: f64, min_step: f64) -> Result<()> {
    if !(backtracking > 0.0 && backtracking < 1.0) {
        return Err(invalid("globalisation.backtracking", backtracking, "must be in (0, 1)"));
    }
    if !(min_step > 0.0 && min_step < 1.0) {
        return Err(invalid("globalisation.min_step", min_step, "must be in (0, 1)"));
    }
    Ok(())
}
