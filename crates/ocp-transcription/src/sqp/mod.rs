//! The multiple-shooting SQP solver: settings, status, counters, warm start and shift.

mod filter;
mod hessian;
mod linearise;
mod settings;
mod solve;
mod status;
mod step;

pub use settings::{
    Globalisation, HessianApproximation, SqpMode, SqpSettings, AUTO_SPARSE_CONDITION,
    CONVERGE_SWITCH_KKT, PROJECTION_FLOOR,
};
pub use solve::Start;
pub use status::{IterationLog, SqpStats, SqpStatus};

use crate::dynamics::Dynamics;
use crate::error::{check_dim, invalid, OcpError, Result};
use crate::integrator::{Integrator, MidpointRecord};
use crate::la::all_finite;
use crate::ocp::Ocp;
use crate::qp::{BoxQp, Condenser, Linearisation, QpForm, Step};
use nalgebra::{DMatrix, DVector};

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
    /// Each interval's converged implicit midpoint substeps at the last linearisation: the
    /// warm start of the line-search trials' Newton iterations, in the real-time iteration
    /// (none otherwise). A converged solve keeps the trials' iterations from scratch: near a
    /// solution its merit comparisons are at the level of the Newton tolerance, where the
    /// warm start's equally converged but different trial states change the iterates' path
    /// (measured on the quasi-Newton cart-pole solve of tests/it/quasi_newton.rs: stalled at
    /// KKT 1.6e-6 instead of converged).
    records: Vec<MidpointRecord>,
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
    /// Line-search trial passes of all solves so far ([`SqpSolver::line_search_trials`]).
    trials: usize,
    /// [`HessianApproximation::GaussNewtonThenExact`]: the switch to the exact Hessian was made
    /// in this solve.
    exact_phase: bool,
    /// Last inertia-correction shift `δ` of this solve (0: none yet).
    inertia_delta: f64,
    /// Shift `δ` on the Hessian blocks of the current linearisation.
    applied_delta: f64,
    /// `Φ(s_k + tΔs_k, u_k + tΔu_k)` of the last line-search trial.
    trial_phi: Vec<DVector<f64>>,
    /// Defects and step saved around a second-order correction.
    d_saved: Vec<DVector<f64>>,
    step_saved: Step,
    filter: filter::Filter,
    /// [`HessianApproximation::GaussNewtonThenQuasiNewton`]: the curvature estimates.
    qn: Option<hessian::QuasiNewton>,
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
        let exact = settings.hessian.is_exact();
        if exact && !model.has_second_order() {
            return Err(OcpError::Unsupported {
                what: "exact Hessian with a model without weighted_hessian",
            });
        }
        if exact
            && settings.hessian != HessianApproximation::ExactProjected
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
        if let Some(t) = &settings.integrator.tail {
            if t.from_interval >= n {
                return Err(invalid(
                    "integrator.tail.from_interval",
                    format!("{} with {n} intervals", t.from_interval),
                    "must be below the problem's interval count",
                ));
            }
        }
        let counts = (0..n).map(|k| settings.integrator.substeps_of(k)).collect();
        let records = if settings.mode == SqpMode::RealTimeIteration
            && settings.integrator.kind == crate::IntegratorKind::ImplicitMidpoint
        {
            (0..n).map(|_| integrators[0].new_record()).collect()
        } else {
            Vec::new()
        };
        let mut solver = Self {
            records,
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
            trials: 0,
            exact_phase: false,
            inertia_delta: 0.0,
            applied_delta: 0.0,
            trial_phi: vec![DVector::zeros(nx); n],
            d_saved: vec![DVector::zeros(nx); n],
            step_saved: Step::new(n, nx, nu),
            filter: filter::Filter::with_capacity(2 * settings.max_iterations + 2),
            qn: match settings.hessian {
                HessianApproximation::GaussNewtonThenQuasiNewton { damped_bfgs, .. } => {
                    Some(hessian::QuasiNewton::new(n, nx, nu, damped_bfgs))
                }
                _ => None,
            },
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
    /// Model evaluations and factorisations of all this solver's integrations so far (every
    /// solve, the warm-start rollouts and linearisations included); the difference of two
    /// readings is the work between them.
    pub fn evaluations(&self) -> crate::Evaluations {
        self.integrators.iter().map(|i| i.evaluations()).sum()
    }
    /// Line-search trial passes of all this solver's solves so far: each integrates the
    /// shooting intervals at one trial step (a rejected one possibly stopped early), so a
    /// sample whose full step is rejected shows one more; the difference of two readings is
    /// the count between them.
    pub fn line_search_trials(&self) -> usize {
        self.trials
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

    /// Sets per-node state references `x_r,0 … x_r,Nc` ([`Ocp::x_ref_nodes`]; each `nx`,
    /// finite); an empty slice returns to the constant reference `x_r` at every node.
    pub fn set_node_references(&mut self, x_refs: &[Vec<f64>]) -> Result<()> {
        if x_refs.is_empty() {
            self.ocp.x_ref_nodes.clear();
            return Ok(());
        }
        check_dim("x_ref_nodes", self.n + 1, x_refs.len())?;
        for r in x_refs {
            check_dim("x_ref_nodes entry", self.nx, r.len())?;
            if !all_finite(r) {
                return Err(invalid(
                    "x_ref_nodes",
                    "non-finite entry",
                    "references must be finite",
                ));
            }
        }
        self.ocp.x_ref_nodes.resize(self.n + 1, DVector::zeros(self.nx));
        for (d, r) in self.ocp.x_ref_nodes.iter_mut().zip(x_refs) {
            d.copy_from_slice(r);
        }
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

    /// Cold start by simulation: `s_0 = x0`, `s_{k+1} = Φ(s_k, u)` with the constant control `u`
    /// (clamped to the bounds), multipliers zero.
    pub fn initialize_by_simulation(&mut self, x0: &[f64], u: &[f64]) -> Result<()> {
        self.initialize_constant(x0, u)?;
        self.initialize_by_rollout(x0)
    }

    /// Cold start by rolling out the current controls: `s_0 = x0`, `s_{k+1} = Φ(s_k, u_k)`,
    /// multipliers zero (a start with zero defects, e.g. when the nodes of a plan from another
    /// model are outside the domain where this model's integration stays finite). `Err` with
    /// the integrator's error when the rollout itself is not finite.
    pub fn initialize_by_rollout(&mut self, x0: &[f64]) -> Result<()> {
        self.roll_out(x0, self.n)?;
        for l in &mut self.lam {
            l.fill(0.0);
        }
        Ok(())
    }

    /// Re-simulates the first `intervals` nodes from `x0` with the current controls:
    /// `s_0 = x0`, `s_{k+1} = Φ(s_k, u_k)` for `k < intervals` (clamped to the horizon); the
    /// later nodes and the multipliers are kept. A warm start whose first defects are zero
    /// when the measured state is away from the shifted plan's first node. `Err` with the
    /// integrator's error when the rollout is not finite (the iterate is then partly
    /// overwritten; the caller restores it).
    pub fn roll_out(&mut self, x0: &[f64], intervals: usize) -> Result<()> {
        check_dim("x0", self.nx, x0.len())?;
        self.s[0].copy_from_slice(x0);
        for k in 0..intervals.min(self.n) {
            let (head, tail) = self.s.split_at_mut(k + 1);
            let c = match self.settings.integrator.adaptive {
                Some(_) => self.integrators[0].choose_substeps(
                    &self.model,
                    head[k].as_slice(),
                    self.u[k].as_slice(),
                    None,
                ),
                None => self.settings.integrator.substeps_of(k),
            };
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
        self.shift_records(m);
    }

    /// Moves the intervals' records with a shift by `m` intervals: the midpoints of the
    /// accepted trial of interval `k + m` start the next linearisation of interval `k` when its
    /// data are unchanged (`Integrator::integrate_with_sensitivities_recorded`); the last `m`
    /// are cleared.
    fn shift_records(&mut self, m: usize) {
        let m = m.min(self.records.len());
        self.records.rotate_left(m);
        let len = self.records.len();
        self.records[len - m..].iter_mut().for_each(MidpointRecord::clear);
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
        // a whole number of intervals moves the nodes and controls unchanged (weights 1 and
        // 0): the records move with them as in `shift`; otherwise no record matches its data
        let m = (tau / dt).round();
        if m * dt == tau {
            self.shift_records(m as usize);
        } else {
            self.records.iter_mut().for_each(MidpointRecord::clear);
        }
        Ok(())
    }

    /// Whether the next linearisation forms the exact Hessian `∇²(ℓ + λᵀΦ)`.
    fn exact_now(&self) -> bool {
        match self.settings.hessian {
            HessianApproximation::GaussNewton => false,
            HessianApproximation::GaussNewtonThenExact { .. } => self.exact_phase,
            HessianApproximation::GaussNewtonThenQuasiNewton { .. } => false,
            _ => true,
        }
    }

    /// Whether the next QP carries curvature of the dynamics (exact or quasi-Newton).
    fn curvature_now(&self) -> bool {
        match self.settings.hessian {
            HessianApproximation::GaussNewtonThenQuasiNewton { .. } => self.exact_phase,
            _ => self.exact_now(),
        }
    }

    /// Whether the stage blocks of the next QP may be indefinite (exact or quasi-Newton, not
    /// projected).
    fn indefinite_blocks_now(&self) -> bool {
        self.curvature_now()
            && !matches!(
                self.settings.hessian,
                HessianApproximation::ExactProjected
                    | HessianApproximation::GaussNewtonThenQuasiNewton { damped_bfgs: true, .. }
            )
    }

    /// Substep count of each interval in the last linearisation (all equal unless
    /// [`IntegratorSettings::adaptive`](crate::IntegratorSettings::adaptive) is set).
    pub fn substep_counts(&self) -> &[usize] {
        &self.counts
    }
}
