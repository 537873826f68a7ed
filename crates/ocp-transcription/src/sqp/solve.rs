//! The SQP loop.

use super::{status_of, Globalisation, IterationLog, SqpMode, SqpSolver, SqpStats, SqpStatus};
use crate::dynamics::Dynamics;
use crate::error::{check_dim, invalid, Result};
use crate::la::{all_finite, norm_inf};
use crate::qp::QpFailure;
use std::time::Instant;

/// The start a [`SqpSolver::solve_with_fallback_starts`] ended up using.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Start {
    /// The iterate as given.
    Given,
    /// The given controls rolled out from `x0` ([`SqpSolver::initialize_by_rollout`]).
    RolledOutControls,
    /// The reference control (clamped into the bounds) rolled out from `x0`.
    RolledOutReference,
}

impl<D: Dynamics> SqpSolver<D> {
    /// [`SqpSolver::solve`] from the current iterate; when the dynamics are not finite there
    /// (status [`SqpStatus::NonFiniteDynamics`] before any iteration, e.g. nodes of a linear
    /// model's plan where the nonlinear model's integration overflows), from the current
    /// controls rolled out from `x0`, and when that rollout is not finite either, from the
    /// reference control rolled out. Returns the last solve's counters and the start used
    /// (the first start's status when no rollout is finite).
    pub fn solve_with_fallback_starts(&mut self, x0: &[f64]) -> Result<(SqpStats, Start)> {
        let st = self.solve(x0)?;
        if !(st.iterations == 0 && st.status == SqpStatus::NonFiniteDynamics) {
            return Ok((st, Start::Given));
        }
        let elapsed = st.time_total;
        let with_time = |mut s: SqpStats| {
            s.time_total += elapsed;
            s
        };
        if self.initialize_by_rollout(x0).is_ok() {
            let s = self.solve(x0)?;
            return Ok((with_time(s), Start::RolledOutControls));
        }
        let u = self.ocp.u_ref.clone();
        self.initialize_constant(x0, u.as_slice())?;
        if self.initialize_by_rollout(x0).is_ok() {
            let s = self.solve(x0)?;
            return Ok((with_time(s), Start::RolledOutReference));
        }
        self.stats = st;
        Ok((st, Start::Given))
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
        let evaluations0 = self.evaluations();
        self.stats = SqpStats::default();
        if let Globalisation::MeritLineSearch { adaptive_penalty: true, .. } =
            self.settings.globalisation
        {
            self.merit_nu = 0.0;
        }
        self.log.clear();
        self.exact_phase = false;
        self.inertia_delta = 0.0;
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
            self.applied_delta = 0.0;
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
            if let Some(switch_kkt) = self.settings.hessian.switch_kkt() {
                // from the next linearisation on (the quasi-Newton estimate from this one on)
                self.exact_phase |= kkt <= switch_kkt;
            }
            if self.qn.is_some() {
                self.quasi_newton_update(it == 0);
            }
            if !rti && kkt <= self.settings.kkt_tolerance {
                status = SqpStatus::Solved;
                break;
            }
            if it >= max_it {
                status = if rti { SqpStatus::RealTimeIteration } else { SqpStatus::MaxIterations };
                break;
            }
            let qp_iters = match self.solve_qp_with_recovery() {
                Ok(q) => q,
                Err(f) => {
                    status = f.status();
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
            let mut t = self.step_length(it == 0);
            let hybrid = self.settings.hessian.is_hybrid();
            if hybrid && ((self.exact_phase && t != Some(1.0)) || t.is_none()) {
                t = match self.levenberg_marquardt_retries(it == 0, t) {
                    Ok(t) => t,
                    Err(f) => {
                        status = f.status();
                        break;
                    }
                };
            }
            let record = |step_length| IterationLog {
                iteration: it,
                cost,
                kkt,
                constraint_violation: viol,
                step_norm,
                step_length,
                qp_iterations: qp_iters,
            };
            let Some(t) = t else {
                status = SqpStatus::LineSearchFailed;
                self.log.push(record(0.0));
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
            self.log.push(record(t));
            it += 1;
            self.stats.iterations = it;
            if rti {
                status = SqpStatus::RealTimeIteration;
                break;
            }
        }
        self.stats.status = status;
        self.stats.integrator_calls = self.integrator_calls() - calls0;
        self.stats.evaluations = self.evaluations() - evaluations0;
        self.stats.time_total = start.elapsed().as_secs_f64();
        Ok(self.stats)
    }
}

impl QpFailure {
    /// The SQP status a failed QP ends the solve with.
    fn status(self) -> SqpStatus {
        match self {
            Self::Infeasible => SqpStatus::QpInfeasible,
            Self::Failed => SqpStatus::QpFailed,
        }
    }
}
