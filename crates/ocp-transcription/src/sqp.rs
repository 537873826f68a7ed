//! The multiple-shooting SQP solver: settings, status, counters, warm start and shift.

use crate::dynamics::Dynamics;
use crate::error::{check_dim, invalid, OcpError, Result};
use crate::integrator::{Integrator, IntegratorSettings};
use crate::la::{all_finite, gemv, gemv_t, norm_inf};
use crate::ocp::Ocp;
use crate::qp::{
    solve_condensed_clarabel, solve_sparse_clarabel, BoxQp, Condenser, Linearisation, QpFailure,
    QpForm, Step,
};
use nalgebra::{DMatrix, DVector};
use std::time::Instant;

/// [`QpForm::Auto`] switches to the sparse multiple-shooting QP when the Cholesky-based
/// condition estimate of the condensed Hessian exceeds this (a condensed solve would keep
/// fewer than ~6 digits of the step).
pub const AUTO_SPARSE_CONDITION: f64 = 1e10;

/// Hessian of the QP subproblems.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum HessianApproximation {
    /// Gauss–Newton: the cost Hessian (exact for the quadratic cost (34), no integrator work).
    GaussNewton,
    /// Exact Hessian of the Lagrangian (adds `∇²(λᵀΦ)` from the integrators; needs
    /// [`Dynamics::weighted_hessian`], an explicit integrator and a condensed QP form).
    /// Indefinite condensed Hessians are regularised by `δI` until a Cholesky succeeds.
    Exact,
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
    /// Backtracking on the ℓ1 merit `J + ν Σ‖defects‖₁` with the Armijo condition.
    MeritLineSearch {
        /// Armijo constant in (0, 0.5). Typical 1e-4.
        armijo: f64,
        /// Backtracking factor in (0, 1). Typical 0.5.
        backtracking: f64,
        /// Smallest step before giving up (status [`SqpStatus::LineSearchFailed`]), in (0, 1).
        min_step: f64,
    },
}

impl Globalisation {
    /// Merit line search with `armijo = 1e-4`, `backtracking = 0.5`, `min_step = 1e-6`.
    pub fn merit() -> Self {
        Globalisation::MeritLineSearch { armijo: 1e-4, backtracking: 0.5, min_step: 1e-6 }
    }
}

/// What one call of [`SqpSolver::solve`] does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum SqpMode {
    /// Iterate to the KKT tolerance or the iteration limit.
    Sqp,
    /// Real-time iteration: exactly one linearisation, QP and step per call.
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
    /// Integrate the shooting intervals of a linearisation on the rayon thread pool
    /// (Gauss–Newton path; exact-Hessian sweeps and line-search trials stay sequential) (default false).
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
        }
    }
}

impl SqpSettings {
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
        match self.globalisation {
            Globalisation::FullStep => {}
            Globalisation::FixedRelaxation { alpha } => {
                if !(alpha > 0.0 && alpha <= 1.0) {
                    return Err(invalid("globalisation.alpha", alpha, "must be in (0, 1]"));
                }
            }
            Globalisation::MeritLineSearch { armijo, backtracking, min_step } => {
                if !(armijo > 0.0 && armijo < 0.5) {
                    return Err(invalid("globalisation.armijo", armijo, "must be in (0, 0.5)"));
                }
                if !(backtracking > 0.0 && backtracking < 1.0) {
                    return Err(invalid(
                        "globalisation.backtracking",
                        backtracking,
                        "must be in (0, 1)",
                    ));
                }
                if !(min_step > 0.0 && min_step < 1.0) {
                    return Err(invalid("globalisation.min_step", min_step, "must be in (0, 1)"));
                }
            }
        }
        Ok(())
    }
}

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
    /// One real-time iteration done ([`SqpMode::RealTimeIteration`]).
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
    /// Hessian regularisations (exact Hessian only).
    pub regularisations: usize,
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
    /// [`IntegratorSettings::adaptive`] is set).
    pub mean_substeps: f64,
}

impl Default for SqpStats {
    fn default() -> Self {
        Self {
            status: SqpStatus::Unsolved,
            iterations: 0,
            qp_iterations: 0,
            integrator_calls: 0,
            regularisations: 0,
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

/// Affine model of the linear–quadratic mode.
#[derive(Clone, Debug)]
struct LqModel {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    phi: DVector<f64>,
    x: DVector<f64>,
    u: DVector<f64>,
}

/// Multiple-shooting SQP for an [`Ocp`] over a [`Dynamics`] model.
///
/// Decision variables: nodes `s_0 … s_N` and controls `u_0 … u_{N−1}` (`N = Nc`);
/// constraints `s_0 = x0`, `s_{k+1} = Φ(s_k, u_k)` (the integrator over one interval),
/// bounds. Each iteration linearises (`A_k = ∂Φ/∂s`, `B_k = ∂Φ/∂u`, defects
/// `d_k = Φ(s_k, u_k) − s_{k+1}`), solves the QP
/// `min ½Δwᵀ H Δw + ∇Jᵀ Δw` s.t. `Δs_0 = x0 − s_0`, `Δs_{k+1} = A_kΔs_k + B_kΔu_k + d_k`, bounds,
/// and steps. All workspaces are allocated by [`SqpSolver::new`].
pub struct SqpSolver<D: Dynamics> {
    model: D,
    ocp: Ocp,
    settings: SqpSettings,
    n: usize,
    nx: usize,
    nu: usize,
    integrators: Vec<Integrator>,
    /// Substep count of each interval, fixed during one SQP iteration.
    counts: Vec<usize>,
    s: Vec<DVector<f64>>,
    u: Vec<DVector<f64>>,
    lam: Vec<DVector<f64>>,
    phi: Vec<DVector<f64>>,
    x0: DVector<f64>,
    lin: Linearisation,
    step: Step,
    cond: Condenser,
    boxqp: BoxQp,
    du_flat: DVector<f64>,
    hdyn: DMatrix<f64>,
    lq: Option<LqModel>,
    log: Vec<IterationLog>,
    stats: SqpStats,
    merit_nu: f64,
    tmp_x: DVector<f64>,
    tmp_x2: DVector<f64>,
    tmp_u: DVector<f64>,
    tmp_u2: DVector<f64>,
    inf_lo: DVector<f64>,
    inf_hi: DVector<f64>,
    shift_s: Vec<DVector<f64>>,
    shift_u: Vec<DVector<f64>>,
    shift_l: Vec<DVector<f64>>,
}

impl<D: Dynamics> std::fmt::Debug for SqpSolver<D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SqpSolver")
            .field("nx", &self.nx)
            .field("nu", &self.nu)
            .field("intervals", &self.n)
            .field("settings", &self.settings)
            .field("stats", &self.stats)
            .finish()
    }
}

fn status_of(e: &OcpError) -> SqpStatus {
    match e {
        OcpError::NonFiniteDynamics { .. } => SqpStatus::NonFiniteDynamics,
        _ => SqpStatus::IntegratorFailed,
    }
}

impl<D: Dynamics> SqpSolver<D> {
    /// Validates `ocp` and `settings` against the model and allocates every workspace.
    /// The initial guess is `s_k = x_r`, `u_k = clamp(u_r)`, `λ = 0`.
    pub fn new(model: D, ocp: Ocp, settings: SqpSettings) -> Result<Self> {
        ocp.validate()?;
        settings.validate()?;
        let (nx, nu, n) = (model.nx(), model.nu(), ocp.intervals);
        check_dim("ocp nx (Q rows) vs model.nx()", nx, ocp.nx())?;
        check_dim("ocp nu (R rows) vs model.nu()", nu, ocp.nu())?;
        if nu == 0 {
            return Err(invalid("nu", nu, "the model must have at least one control"));
        }
        let exact = settings.hessian == HessianApproximation::Exact;
        if exact && !model.has_second_order() {
            return Err(OcpError::Unsupported {
                what: "exact Hessian with a model without weighted_hessian",
            });
        }
        if exact
            && settings.qp_form == QpForm::SparseClarabel
            && settings.mode != SqpMode::LinearQuadratic
        {
            // the stage blocks of an exact Hessian are indefinite in general; only the condensed
            // forms can convexify the reduced Hessian
            return Err(OcpError::Unsupported {
                what: "exact Hessian with the sparse QP form (use a condensed form)",
            });
        }
        let dt = ocp.interval();
        let mut integrators = Vec::with_capacity(n);
        // one workspace serves every interval in turn (it stays in cache); the parallel mode
        // needs one per interval
        let count = if settings.parallel_intervals { n } else { 1 };
        for _ in 0..count {
            let mut int = Integrator::new(&model, &settings.integrator, dt)?;
            if exact && settings.mode != SqpMode::LinearQuadratic {
                int.enable_second_order()?;
            }
            integrators.push(int);
        }
        let mut u0 = ocp.u_ref.clone();
        for i in 0..nu {
            u0[i] = u0[i].clamp(ocp.u_min[i], ocp.u_max[i]);
        }
        let counts = vec![settings.integrator.substeps; n];
        let mut solver = Self {
            n,
            nx,
            nu,
            integrators,
            counts,
            s: vec![ocp.x_ref.clone(); n + 1],
            u: vec![u0; n],
            lam: vec![DVector::zeros(nx); n + 1],
            phi: vec![DVector::zeros(nx); n],
            x0: DVector::zeros(nx),
            lin: Linearisation::new(n, nx, nu),
            step: Step::new(n, nx, nu),
            cond: Condenser::new(n, nx, nu),
            boxqp: BoxQp::new(n * nu),
            du_flat: DVector::zeros(n * nu),
            hdyn: DMatrix::zeros(nx + nu, nx + nu),
            lq: None,
            log: Vec::with_capacity(settings.max_iterations + 1),
            stats: SqpStats::default(),
            merit_nu: 0.0,
            tmp_x: DVector::zeros(nx),
            tmp_x2: DVector::zeros(nx),
            tmp_u: DVector::zeros(nu),
            tmp_u2: DVector::zeros(nu),
            inf_lo: DVector::from_element(n * nu, f64::NEG_INFINITY),
            inf_hi: DVector::from_element(n * nu, f64::INFINITY),
            shift_s: vec![DVector::zeros(nx); n + 1],
            shift_u: vec![DVector::zeros(nu); n],
            shift_l: vec![DVector::zeros(nx); n + 1],
            model,
            ocp,
            settings,
        };
        if solver.settings.mode == SqpMode::LinearQuadratic {
            let (x, u) = (solver.ocp.x_ref.clone(), solver.ocp.u_ref.clone());
            solver.linearise_lq_at(x.as_slice(), u.as_slice())?;
        }
        Ok(solver)
    }

    /// (Re)computes the linear–quadratic model at `(x, u)`: `A`, `B` and `Φ(x, u)` of the
    /// chosen integrator. Used by [`SqpMode::LinearQuadratic`]; done at the reference by
    /// [`SqpSolver::new`].
    pub fn linearise_lq_at(&mut self, x: &[f64], u: &[f64]) -> Result<()> {
        check_dim("x", self.nx, x.len())?;
        check_dim("u", self.nu, u.len())?;
        let mut a = DMatrix::zeros(self.nx, self.nx);
        let mut b = DMatrix::zeros(self.nx, self.nu);
        let mut phi = DVector::zeros(self.nx);
        let c = self.integrators[0].choose_substeps(&self.model, x, u, None);
        self.integrators[0].set_substeps(c)?;
        self.integrators[0].integrate_with_sensitivities(
            &self.model,
            x,
            u,
            phi.as_mut_slice(),
            &mut a,
            &mut b,
        )?;
        self.lq = Some(LqModel {
            a,
            b,
            phi,
            x: DVector::from_column_slice(x),
            u: DVector::from_column_slice(u),
        });
        Ok(())
    }

    /// The model.
    pub fn model(&self) -> &D {
        &self.model
    }
    /// Mutable model (e.g. to update its parameters between samples; in
    /// [`SqpMode::LinearQuadratic`] call [`SqpSolver::linearise_lq_at`] afterwards).
    pub fn model_mut(&mut self) -> &mut D {
        &mut self.model
    }
    /// The problem.
    pub fn ocp(&self) -> &Ocp {
        &self.ocp
    }
    /// The settings.
    pub fn settings(&self) -> &SqpSettings {
        &self.settings
    }
    /// Shooting nodes `s_0 … s_N`.
    pub fn states(&self) -> &[DVector<f64>] {
        &self.s
    }
    /// Controls `u_0 … u_{N−1}`.
    pub fn controls(&self) -> &[DVector<f64>] {
        &self.u
    }
    /// Mutable nodes (custom warm start).
    pub fn states_mut(&mut self) -> &mut [DVector<f64>] {
        &mut self.s
    }
    /// Mutable controls (custom warm start; kept within bounds by the caller).
    pub fn controls_mut(&mut self) -> &mut [DVector<f64>] {
        &mut self.u
    }
    /// Multipliers `λ_0 … λ_N` (`λ_{k+1}` of `s_{k+1} = Φ(s_k, u_k)`, `λ_0` of `s_0 = x0`).
    pub fn multipliers(&self) -> &[DVector<f64>] {
        &self.lam
    }
    /// The first control `u_0` (what an MPC applies).
    pub fn first_control(&self) -> &DVector<f64> {
        &self.u[0]
    }
    /// Counters of the last solve.
    pub fn stats(&self) -> &SqpStats {
        &self.stats
    }
    /// Iteration log of the last solve.
    pub fn log(&self) -> &[IterationLog] {
        &self.log
    }

    /// Sets the state and control references (validated; data updated in place).
    pub fn set_references(&mut self, x_ref: &[f64], u_ref: &[f64]) -> Result<()> {
        check_dim("x_ref", self.nx, x_ref.len())?;
        check_dim("u_ref", self.nu, u_ref.len())?;
        if !all_finite(x_ref) || !all_finite(u_ref) {
            return Err(invalid("x_ref/u_ref", "non-finite entry", "references must be finite"));
        }
        self.ocp.x_ref.copy_from_slice(x_ref);
        self.ocp.u_ref.copy_from_slice(u_ref);
        Ok(())
    }

    /// Sets the control bounds (validated; the controls are clamped into them).
    pub fn set_control_bounds(&mut self, u_min: &[f64], u_max: &[f64]) -> Result<()> {
        check_dim("u_min", self.nu, u_min.len())?;
        check_dim("u_max", self.nu, u_max.len())?;
        for i in 0..self.nu {
            if u_min[i].is_nan() || u_max[i].is_nan() || u_min[i] > u_max[i] {
                return Err(invalid(
                    "u_min/u_max",
                    format!("[{}, {}] at {i}", u_min[i], u_max[i]),
                    "need u_min ≤ u_max",
                ));
            }
        }
        self.ocp.u_min.copy_from_slice(u_min);
        self.ocp.u_max.copy_from_slice(u_max);
        for u in &mut self.u {
            for i in 0..self.nu {
                u[i] = u[i].clamp(u_min[i], u_max[i]);
            }
        }
        Ok(())
    }

    /// Cold start: every node `x`, every control `u` (clamped), multipliers zero.
    pub fn initialize_constant(&mut self, x: &[f64], u: &[f64]) -> Result<()> {
        check_dim("x", self.nx, x.len())?;
        check_dim("u", self.nu, u.len())?;
        for s in &mut self.s {
            s.copy_from_slice(x);
        }
        for uk in &mut self.u {
            for i in 0..self.nu {
                uk[i] = u[i].clamp(self.ocp.u_min[i], self.ocp.u_max[i]);
            }
        }
        for l in &mut self.lam {
            l.fill(0.0);
        }
        Ok(())
    }

    /// Cold start by simulation: `s_0 = x0`, `s_{k+1} = Φ(s_k, u)` with the constant control `u`.
    pub fn initialize_by_simulation(&mut self, x0: &[f64], u: &[f64]) -> Result<()> {
        self.initialize_constant(x0, u)?;
        for k in 0..self.n {
            let (head, tail) = self.s.split_at_mut(k + 1);
            let c = self.integrators[0].choose_substeps(&self.model, head[k].as_slice(), u, None);
            self.integrators[0].set_substeps(c)?;
            self.counts[k] = c;
            self.integrators[0].integrate(
                &self.model,
                head[k].as_slice(),
                self.u[k].as_slice(),
                tail[0].as_mut_slice(),
            )?;
        }
        Ok(())
    }

    /// Shifts the iterate by `m` whole intervals (warm start for the next sample when the
    /// sampling time equals `m Δt`); the tail repeats the last node/control.
    pub fn shift(&mut self, m: usize) {
        let n = self.n;
        for k in 0..=n {
            let j = (k + m).min(n);
            self.shift_s[k].copy_from(&self.s[j]);
            self.shift_l[k].copy_from(&self.lam[j]);
        }
        for k in 0..n {
            self.shift_u[k].copy_from(&self.u[(k + m).min(n - 1)]);
        }
        std::mem::swap(&mut self.s, &mut self.shift_s);
        std::mem::swap(&mut self.lam, &mut self.shift_l);
        std::mem::swap(&mut self.u, &mut self.shift_u);
    }

    /// Shifts the iterate by a time `tau ≥ 0` (any sampling time, not a multiple of `Δt`):
    /// nodes and multipliers by linear interpolation at `t_k + τ`, controls by the
    /// piecewise-constant plan at the interval midpoints `t_k + Δt/2 + τ` (clamped to the horizon).
    pub fn shift_time(&mut self, tau: f64) -> Result<()> {
        if !(tau >= 0.0 && tau.is_finite()) {
            return Err(invalid("tau", tau, "must be finite and ≥ 0"));
        }
        let n = self.n;
        let dt = self.ocp.interval();
        for k in 0..=n {
            let t = (k as f64 + tau / dt).min(n as f64);
            let i = (t.floor() as usize).min(n);
            let j = (i + 1).min(n);
            let w = t - i as f64;
            self.shift_s[k].copy_from(&self.s[i]);
            self.shift_s[k] *= 1.0 - w;
            self.shift_s[k].axpy(w, &self.s[j], 1.0);
            self.shift_l[k].copy_from(&self.lam[i]);
            self.shift_l[k] *= 1.0 - w;
            self.shift_l[k].axpy(w, &self.lam[j], 1.0);
        }
        for k in 0..n {
            let t = k as f64 + 0.5 + tau / dt;
            let i = (t.floor() as usize).min(n - 1);
            self.shift_u[k].copy_from(&self.u[i]);
        }
        std::mem::swap(&mut self.s, &mut self.shift_s);
        std::mem::swap(&mut self.lam, &mut self.shift_l);
        std::mem::swap(&mut self.u, &mut self.shift_u);
        Ok(())
    }

    /// Substep count of each interval in the last linearisation (all equal unless
    /// [`IntegratorSettings::adaptive`] is set).
    pub fn substep_counts(&self) -> &[usize] {
        &self.counts
    }

    /// Chooses every interval's substep count from the current iterate (adaptive table:
    /// nodes `s_k`, `s_{k+1}` and control `u_k`). They stay fixed for the linearisation and
    /// the line search of an iteration, so `A_k`, `B_k` are the exact derivatives of the
    /// map whose defects are driven to zero. At the first iteration of a `solve` (`fresh`)
    /// they are chosen anew; at later ones a count may only grow (`max` with the new choice):
    /// a count that went down and up again would keep changing the map and stall the SQP
    /// (measured), while non-decreasing counts settle after finitely many changes and still
    /// meet the table at the final iterate.
    fn choose_counts(&mut self, fresh: bool) {
        if self.settings.integrator.adaptive.is_none() {
            return;
        }
        for k in 0..self.n {
            let c = self.integrators[0].choose_substeps(
                &self.model,
                self.s[k].as_slice(),
                self.u[k].as_slice(),
                Some(self.s[k + 1].as_slice()),
            );
            self.counts[k] = if fresh { c } else { c.max(self.counts[k]) };
        }
    }

    fn integrator_calls(&self) -> usize {
        self.integrators.iter().map(|i| i.calls()).sum()
    }

    /// Linearises at the current iterate: `Φ`, `A`, `B`, defects, Hessian blocks, gradients, bounds.
    fn linearise(&mut self, with_hessian: bool, fresh_counts: bool) -> Result<()> {
        let n = self.n;
        let exact = with_hessian && self.settings.hessian == HessianApproximation::Exact;
        let t0 = Instant::now();
        if self.lq.is_none() {
            self.choose_counts(fresh_counts);
            self.stats.mean_substeps =
                self.counts.iter().sum::<usize>() as f64 / self.n.max(1) as f64;
        }
        if self.settings.parallel_intervals && !exact && self.lq.is_none() {
            use rayon::prelude::*;
            let (model, s, u, counts) = (&self.model, &self.s, &self.u, &self.counts);
            self.integrators
                .par_iter_mut()
                .zip(self.phi.par_iter_mut())
                .zip(self.lin.a.par_iter_mut())
                .zip(self.lin.b.par_iter_mut())
                .enumerate()
                .try_for_each(|(k, (((int, phi), a), b))| {
                    int.set_substeps(counts[k])?;
                    int.integrate_with_sensitivities(
                        model,
                        s[k].as_slice(),
                        u[k].as_slice(),
                        phi.as_mut_slice(),
                        a,
                        b,
                    )
                })?;
        }
        for k in 0..n {
            if self.settings.parallel_intervals && !exact && self.lq.is_none() {
                break;
            }
            if let Some(lq) = &self.lq {
                let (phi, a, b) = (&mut self.phi[k], &mut self.lin.a[k], &mut self.lin.b[k]);
                a.copy_from(&lq.a);
                b.copy_from(&lq.b);
                phi.copy_from(&lq.phi);
                self.tmp_x.copy_from(&self.s[k]);
                self.tmp_x -= &lq.x;
                gemv(phi.as_mut_slice(), &lq.a, self.tmp_x.as_slice(), 1.0, true);
                self.tmp_u.copy_from(&self.u[k]);
                self.tmp_u -= &lq.u;
                gemv(phi.as_mut_slice(), &lq.b, self.tmp_u.as_slice(), 1.0, true);
                self.lin.hq[k].fill(0.0);
                continue;
            }
            self.integrators[0].set_substeps(self.counts[k])?;
            if exact {
                self.integrators[0].integrate_with_hessian(
                    &self.model,
                    self.s[k].as_slice(),
                    self.u[k].as_slice(),
                    self.lam[k + 1].as_slice(),
                    self.phi[k].as_mut_slice(),
                    &mut self.lin.a[k],
                    &mut self.lin.b[k],
                    &mut self.hdyn,
                )?;
                let nx = self.nx;
                self.lin.hq[k].copy_from(&self.hdyn.view((0, 0), (nx, nx)));
                self.lin.hr[k].copy_from(&self.hdyn.view((nx, nx), (self.nu, self.nu)));
                self.lin.hs[k].copy_from(&self.hdyn.view((nx, 0), (self.nu, nx)));
            } else {
                self.integrators[0].integrate_with_sensitivities(
                    &self.model,
                    self.s[k].as_slice(),
                    self.u[k].as_slice(),
                    self.phi[k].as_mut_slice(),
                    &mut self.lin.a[k],
                    &mut self.lin.b[k],
                )?;
            }
        }
        self.stats.time_integration += t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let exact_blocks = exact && self.lq.is_none();
        let dt = self.ocp.interval();
        let lm = self.settings.levenberg_marquardt;
        for k in 0..=n {
            let w = self.ocp.node_weight(k);
            // Hessian blocks
            if !exact_blocks || k == n {
                self.lin.hq[k].fill(0.0);
            }
            crate::la::axpy(self.lin.hq[k].as_mut_slice(), w, self.ocp.q.as_slice());
            if k == n {
                self.lin.hq[k] += &self.ocp.terminal;
            }
            for i in 0..self.nx {
                self.lin.hq[k][(i, i)] += lm;
            }
            // gradient q_k = w Q (s_k − x_r) (+ P (s_N − x_r))
            self.tmp_x.copy_from(&self.s[k]);
            self.tmp_x -= &self.ocp.x_ref;
            gemv(self.lin.q[k].as_mut_slice(), &self.ocp.q, self.tmp_x.as_slice(), w, false);
            if k == n {
                gemv(
                    self.lin.q[k].as_mut_slice(),
                    &self.ocp.terminal,
                    self.tmp_x.as_slice(),
                    1.0,
                    true,
                );
            }
            // step bounds on nodes
            for i in 0..self.nx {
                self.lin.dx_lo[k][i] = self.ocp.x_min[i] - self.s[k][i];
                self.lin.dx_hi[k][i] = self.ocp.x_max[i] - self.s[k][i];
            }
            if k < n {
                if !exact_blocks {
                    self.lin.hr[k].fill(0.0);
                    self.lin.hs[k].fill(0.0);
                }
                crate::la::axpy(self.lin.hr[k].as_mut_slice(), dt, self.ocp.r.as_slice());
                for i in 0..self.nu {
                    self.lin.hr[k][(i, i)] += lm;
                }
                self.tmp_u.copy_from(&self.u[k]);
                self.tmp_u -= &self.ocp.u_ref;
                gemv(self.lin.r[k].as_mut_slice(), &self.ocp.r, self.tmp_u.as_slice(), dt, false);
                for i in 0..self.nu {
                    self.lin.du_lo[k][i] = self.ocp.u_min[i] - self.u[k][i];
                    self.lin.du_hi[k][i] = self.ocp.u_max[i] - self.u[k][i];
                }
                self.lin.d[k].copy_from(&self.phi[k]);
                self.lin.d[k] -= &self.s[k + 1];
            }
        }
        self.lin.g0.copy_from(&self.x0);
        self.lin.g0 -= &self.s[0];
        self.stats.time_condensing += t1.elapsed().as_secs_f64();
        Ok(())
    }

    /// Cost `J` at `(s, u)`.
    fn cost_of(&mut self, s: &[DVector<f64>], u: &[DVector<f64>]) -> f64 {
        let n = self.n;
        let dt = self.ocp.interval();
        let mut j = 0.0;
        for k in 0..=n {
            self.tmp_x.copy_from(&s[k]);
            self.tmp_x -= &self.ocp.x_ref;
            gemv(self.tmp_x2.as_mut_slice(), &self.ocp.q, self.tmp_x.as_slice(), 1.0, false);
            j += 0.5 * self.ocp.node_weight(k) * self.tmp_x.dot(&self.tmp_x2);
            if k == n {
                gemv(
                    self.tmp_x2.as_mut_slice(),
                    &self.ocp.terminal,
                    self.tmp_x.as_slice(),
                    1.0,
                    false,
                );
                j += 0.5 * self.tmp_x.dot(&self.tmp_x2);
            }
            if k < n {
                self.tmp_u.copy_from(&u[k]);
                self.tmp_u -= &self.ocp.u_ref;
                gemv(self.tmp_u2.as_mut_slice(), &self.ocp.r, self.tmp_u.as_slice(), 1.0, false);
                j += 0.5 * dt * self.tmp_u.dot(&self.tmp_u2);
            }
        }
        j
    }

    /// State-bound violation (max) of node `s`.
    fn bound_violation(&self, s: &DVector<f64>) -> f64 {
        let mut v = 0.0_f64;
        for i in 0..self.nx {
            v = v.max(self.ocp.x_min[i] - s[i]).max(s[i] - self.ocp.x_max[i]);
        }
        v
    }

    /// KKT residual (max norm) and constraint violation at the current linearisation.
    fn kkt(&mut self) -> (f64, f64) {
        let n = self.n;
        let mut stat = 0.0_f64;
        for k in 0..n {
            self.tmp_u.copy_from(&self.lin.r[k]);
            gemv_t(
                self.tmp_u.as_mut_slice(),
                &self.lin.b[k],
                self.lam[k + 1].as_slice(),
                1.0,
                true,
            );
            for i in 0..self.nu {
                let u = self.u[k][i];
                let proj = (u - self.tmp_u[i]).clamp(self.ocp.u_min[i], self.ocp.u_max[i]);
                stat = stat.max((u - proj).abs());
            }
        }
        for k in 1..=n {
            self.tmp_x.copy_from(&self.lin.q[k]);
            if k < n {
                gemv_t(
                    self.tmp_x.as_mut_slice(),
                    &self.lin.a[k],
                    self.lam[k + 1].as_slice(),
                    1.0,
                    true,
                );
            }
            self.tmp_x -= &self.lam[k];
            for i in 0..self.nx {
                let s = self.s[k][i];
                let proj = (s - self.tmp_x[i]).clamp(self.ocp.x_min[i], self.ocp.x_max[i]);
                stat = stat.max((s - proj).abs());
            }
        }
        let mut viol = norm_inf(self.lin.g0.as_slice());
        for k in 0..n {
            viol = viol.max(norm_inf(self.lin.d[k].as_slice()));
            viol = viol.max(self.bound_violation(&self.s[k + 1]));
        }
        if stat.is_nan() || viol.is_nan() {
            return (f64::NAN, f64::NAN);
        }
        (stat.max(viol), viol)
    }

    /// Solves the QP of the current linearisation into `self.step`; returns QP iterations.
    fn solve_qp(&mut self) -> std::result::Result<usize, QpFailure> {
        let tol = self.settings.qp_tolerance;
        let max_it = self.settings.qp_max_iterations;
        let form = match self.settings.qp_form {
            QpForm::Auto | QpForm::CondensedDense if self.ocp.has_state_bounds() => {
                QpForm::CondensedClarabel
            }
            QpForm::Auto => QpForm::CondensedDense,
            f => f,
        };
        let mut form = form;
        if form != QpForm::SparseClarabel {
            let t = Instant::now();
            self.cond.condense(&self.lin);
            self.stats.time_condensing += t.elapsed().as_secs_f64();
            // Auto: an ill-conditioned condensed Hessian (unstable dynamics over the horizon)
            // loses digits in any condensed solve; the multiple-shooting QP does not
            if self.settings.qp_form == QpForm::Auto
                && self.settings.hessian == HessianApproximation::GaussNewton
            {
                let t = Instant::now();
                let cond = self.boxqp.condition_estimate(&self.cond.hc);
                self.stats.time_qp += t.elapsed().as_secs_f64();
                if cond.is_finite() && cond > AUTO_SPARSE_CONDITION {
                    form = QpForm::SparseClarabel;
                }
            }
        }
        if form == QpForm::SparseClarabel {
            let t = Instant::now();
            let r = solve_sparse_clarabel(&self.lin, &mut self.step, tol, max_it as u32);
            self.stats.time_qp += t.elapsed().as_secs_f64();
            return r;
        }
        let t = Instant::now();
        let exact = self.settings.hessian == HessianApproximation::Exact && self.lq.is_none();
        let mut iters = 0;
        let mut delta = 0.0;
        let diag_scale =
            1.0 + (0..self.cond.hc.nrows()).map(|i| self.cond.hc[(i, i)].abs()).fold(0.0, f64::max);
        for attempt in 0..12 {
            if attempt > 0 {
                // convexify an indefinite exact Hessian: H + δI
                let new_delta = if delta == 0.0 { 1e-8 * diag_scale } else { 10.0 * delta };
                for i in 0..self.cond.hc.nrows() {
                    self.cond.hc[(i, i)] += new_delta - delta;
                }
                delta = new_delta;
                self.stats.regularisations += 1;
            }
            let r = match form {
                QpForm::CondensedClarabel => {
                    if exact && !self.boxqp_is_pd() {
                        continue;
                    }
                    for mu in self.step.mu.iter_mut() {
                        mu.fill(0.0);
                    }
                    solve_condensed_clarabel(
                        &self.cond,
                        &self.lin,
                        &mut self.step,
                        &mut self.du_flat,
                        tol,
                        max_it as u32,
                    )
                }
                _ => {
                    let r = self.boxqp.solve(
                        &self.cond.hc,
                        &self.cond.hv,
                        &self.cond.lo,
                        &self.cond.hi,
                        tol,
                        max_it,
                    );
                    if r.is_ok() {
                        self.du_flat.copy_from(self.boxqp.solution());
                        for mu in self.step.mu.iter_mut() {
                            mu.fill(0.0);
                        }
                    }
                    r
                }
            };
            match r {
                Ok(it) => {
                    iters += it;
                    self.stats.time_qp += t.elapsed().as_secs_f64();
                    let t2 = Instant::now();
                    self.cond.expand(&self.lin, &self.du_flat, &mut self.step);
                    self.stats.time_condensing += t2.elapsed().as_secs_f64();
                    return Ok(iters);
                }
                Err(QpFailure::Failed) if exact => continue,
                Err(e) => {
                    self.stats.time_qp += t.elapsed().as_secs_f64();
                    return Err(e);
                }
            }
        }
        self.stats.time_qp += t.elapsed().as_secs_f64();
        Err(QpFailure::Failed)
    }

    /// Whether the condensed Hessian admits a Cholesky factorisation.
    fn boxqp_is_pd(&mut self) -> bool {
        self.boxqp.solve(&self.cond.hc, &self.cond.hv, &self.inf_lo, &self.inf_hi, 1e-12, 1).is_ok()
    }

    /// Merit `J + ν (Σ‖d‖₁ + ‖x0 − s_0‖₁ + state-bound violations)` at `(s + tΔs, u + tΔu)`;
    /// `None` when the dynamics fail there. Uses the shift buffers as trial storage.
    fn merit_at(&mut self, t: f64) -> Option<f64> {
        let n = self.n;
        for k in 0..=n {
            self.shift_s[k].copy_from(&self.s[k]);
            self.shift_s[k].axpy(t, &self.step.ds[k], 1.0);
        }
        for k in 0..n {
            self.shift_u[k].copy_from(&self.u[k]);
            self.shift_u[k].axpy(t, &self.step.du[k], 1.0);
            for i in 0..self.nu {
                self.shift_u[k][i] = self.shift_u[k][i].clamp(self.ocp.u_min[i], self.ocp.u_max[i]);
            }
        }
        let t0 = Instant::now();
        let mut c = 0.0;
        for i in 0..self.nx {
            c += (self.x0[i] - self.shift_s[0][i]).abs();
        }
        for k in 0..n {
            if self.integrators[0].set_substeps(self.counts[k]).is_err()
                || self.integrators[0]
                    .integrate(
                        &self.model,
                        self.shift_s[k].as_slice(),
                        self.shift_u[k].as_slice(),
                        self.tmp_x.as_mut_slice(),
                    )
                    .is_err()
            {
                self.stats.time_integration += t0.elapsed().as_secs_f64();
                return None;
            }
            for i in 0..self.nx {
                c += (self.tmp_x[i] - self.shift_s[k + 1][i]).abs();
                c += (self.ocp.x_min[i] - self.shift_s[k + 1][i]).max(0.0)
                    + (self.shift_s[k + 1][i] - self.ocp.x_max[i]).max(0.0);
            }
        }
        self.stats.time_integration += t0.elapsed().as_secs_f64();
        let s = std::mem::take(&mut self.shift_s);
        let u = std::mem::take(&mut self.shift_u);
        let j = self.cost_of(&s, &u);
        self.shift_s = s;
        self.shift_u = u;
        let m = j + self.merit_nu * c;
        if m.is_finite() {
            Some(m)
        } else {
            None
        }
    }

    /// Chooses the step length; `None` when the line search fails.
    fn step_length(&mut self) -> Option<f64> {
        match self.settings.globalisation {
            Globalisation::FullStep => Some(1.0),
            Globalisation::FixedRelaxation { alpha } => Some(alpha),
            Globalisation::MeritLineSearch { armijo, backtracking, min_step } => {
                let n = self.n;
                let mut lam_max = 0.0_f64;
                for k in 0..=n {
                    lam_max = lam_max
                        .max(norm_inf(self.step.lam[k].as_slice()))
                        .max(norm_inf(self.step.mu[k].as_slice()));
                }
                if self.merit_nu < 1.1 * lam_max {
                    self.merit_nu = 2.0 * lam_max;
                }
                // directional derivative: ∇Jᵀ Δw − ν c(w)
                let mut djdw = 0.0;
                for k in 0..=n {
                    djdw += self.lin.q[k].dot(&self.step.ds[k]);
                    if k < n {
                        djdw += self.lin.r[k].dot(&self.step.du[k]);
                    }
                }
                let mut c0 = self.lin.g0.lp_norm(1);
                for k in 0..n {
                    c0 += self.lin.d[k].lp_norm(1);
                    for i in 0..self.nx {
                        let s = self.s[k + 1][i];
                        c0 += (self.ocp.x_min[i] - s).max(0.0) + (s - self.ocp.x_max[i]).max(0.0);
                    }
                }
                let s_ref = std::mem::take(&mut self.s);
                let u_ref = std::mem::take(&mut self.u);
                let j0 = self.cost_of(&s_ref, &u_ref);
                self.s = s_ref;
                self.u = u_ref;
                let phi0 = j0 + self.merit_nu * c0;
                let dd = (djdw - self.merit_nu * c0).min(0.0);
                let mut t = 1.0;
                loop {
                    if let Some(phi) = self.merit_at(t) {
                        if phi <= phi0 + armijo * t * dd + 1e-14 * phi0.abs() {
                            return Some(t);
                        }
                    }
                    t *= backtracking;
                    if t < min_step {
                        return None;
                    }
                }
            }
        }
    }

    /// Runs the SQP from the current iterate for the initial state `x0`.
    ///
    /// Returns the counters (also kept in [`SqpSolver::stats`]); `Err` only for a wrong
    /// `x0` (dimension or non-finite). Numerical failures end in a [`SqpStatus`].
    pub fn solve(&mut self, x0: &[f64]) -> Result<SqpStats> {
        check_dim("x0", self.nx, x0.len())?;
        if !all_finite(x0) {
            return Err(invalid("x0", "non-finite entry", "the initial state must be finite"));
        }
        let start = Instant::now();
        let calls0 = self.integrator_calls();
        self.stats = SqpStats::default();
        self.log.clear();
        self.x0.copy_from_slice(x0);
        let rti = self.settings.mode == SqpMode::RealTimeIteration;
        let max_it = if rti { 1 } else { self.settings.max_iterations };
        let status;
        let mut it = 0;
        loop {
            if let Err(e) = self.linearise(true, it == 0) {
                status = status_of(&e);
                break;
            }
            let (kkt, viol) = self.kkt();
            let s = std::mem::take(&mut self.s);
            let u = std::mem::take(&mut self.u);
            let cost = self.cost_of(&s, &u);
            self.s = s;
            self.u = u;
            self.stats.kkt = kkt;
            self.stats.cost = cost;
            self.stats.constraint_violation = viol;
            if !kkt.is_finite() {
                status = SqpStatus::NonFiniteDynamics;
                break;
            }
            if !rti && kkt <= self.settings.kkt_tolerance {
                status = SqpStatus::Solved;
                break;
            }
            if it >= max_it {
                status = if rti { SqpStatus::RealTimeIteration } else { SqpStatus::MaxIterations };
                break;
            }
            let qp_iters = match self.solve_qp() {
                Ok(q) => q,
                Err(QpFailure::Infeasible) => {
                    status = SqpStatus::QpInfeasible;
                    break;
                }
                Err(QpFailure::Failed) => {
                    status = SqpStatus::QpFailed;
                    break;
                }
            };
            self.stats.qp_iterations += qp_iters;
            let mut step_norm = 0.0_f64;
            for k in 0..=self.n {
                step_norm = step_norm.max(norm_inf(self.step.ds[k].as_slice()));
                if k < self.n {
                    step_norm = step_norm.max(norm_inf(self.step.du[k].as_slice()));
                }
            }
            let Some(t) = self.step_length() else {
                status = SqpStatus::LineSearchFailed;
                self.log.push(IterationLog {
                    iteration: it,
                    cost,
                    kkt,
                    constraint_violation: viol,
                    step_norm,
                    step_length: 0.0,
                    qp_iterations: qp_iters,
                });
                break;
            };
            for k in 0..=self.n {
                self.s[k].axpy(t, &self.step.ds[k], 1.0);
                self.lam[k] *= 1.0 - t;
                self.lam[k].axpy(t, &self.step.lam[k], 1.0);
                if k < self.n {
                    self.u[k].axpy(t, &self.step.du[k], 1.0);
                    for i in 0..self.nu {
                        self.u[k][i] = self.u[k][i].clamp(self.ocp.u_min[i], self.ocp.u_max[i]);
                    }
                }
            }
            self.log.push(IterationLog {
                iteration: it,
                cost,
                kkt,
                constraint_violation: viol,
                step_norm,
                step_length: t,
                qp_iterations: qp_iters,
            });
            it += 1;
            self.stats.iterations = it;
            if rti {
                status = SqpStatus::RealTimeIteration;
                break;
            }
        }
        self.stats.status = status;
        self.stats.integrator_calls = self.integrator_calls() - calls0;
        self.stats.time_total = start.elapsed().as_secs_f64();
        Ok(self.stats)
    }
}
