//! The QP of an iteration and the step length (globalisation).

use super::{Globalisation, SqpSolver, AUTO_SPARSE_CONDITION};
use crate::dynamics::Dynamics;
use crate::la::norm_inf;
use crate::qp::{solve_condensed_clarabel, solve_sparse_clarabel, QpFailure, QpForm};
use std::time::Instant;

impl<D: Dynamics> SqpSolver<D> {
    /// Solves the QP of the current linearisation into `self.step`; returns QP iterations.
    pub(super) fn solve_qp(&mut self) -> std::result::Result<usize, QpFailure> {
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
            // loses digits in any condensed solve; the multiple-shooting QP does not. With
            // semidefinite blocks an estimate of ∞ (no Cholesky factor) is the extreme of
            // this, round-off on a condition number beyond 1/ε, so it switches too.
            if self.settings.qp_form == QpForm::Auto && !self.indefinite_blocks_now() {
                let t = Instant::now();
                let cond = self.boxqp.condition_estimate(&self.cond.hc);
                self.stats.time_qp += t.elapsed().as_secs_f64();
                if cond > AUTO_SPARSE_CONDITION {
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
        let mut exact = self.curvature_now() && self.lq.is_none();
        if exact && self.settings.hessian.is_hybrid() && !self.inertia_correction() {
            // no shift made the reduced Hessian definite: take the Gauss–Newton step
            self.gauss_newton_blocks();
            let t = Instant::now();
            self.cond.condense(&self.lin);
            self.stats.time_condensing += t.elapsed().as_secs_f64();
            self.stats.gauss_newton_fallbacks += 1;
            exact = false;
        }
        let t = Instant::now();
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

    /// [`Self::solve_qp`], then, with [`crate::SqpSettings::qp_recovery`], up to six more
    /// attempts with a growing Levenberg–Marquardt term on the Hessian blocks of this
    /// linearisation (the next linearisation rebuilds them).
    pub(super) fn solve_qp_with_recovery(&mut self) -> std::result::Result<usize, QpFailure> {
        let r = self.solve_qp();
        if !self.settings.qp_recovery || !matches!(r, Err(QpFailure::Failed)) {
            return r;
        }
        let mut scale = 0.0_f64;
        for k in 0..=self.n {
            for i in 0..self.nx {
                scale = scale.max(self.lin.hq[k][(i, i)].abs());
            }
            if k < self.n {
                for i in 0..self.nu {
                    scale = scale.max(self.lin.hr[k][(i, i)].abs());
                }
            }
        }
        let mut mu_prev = 0.0;
        for attempt in 0..7 {
            let mu = 1e-5 * 10f64.powi(attempt) * (1.0 + scale);
            for k in 0..=self.n {
                for i in 0..self.nx {
                    self.lin.hq[k][(i, i)] += mu - mu_prev;
                }
                if k < self.n {
                    for i in 0..self.nu {
                        self.lin.hr[k][(i, i)] += mu - mu_prev;
                    }
                }
            }
            mu_prev = mu;
            self.stats.qp_recoveries += 1;
            match self.solve_qp() {
                Err(QpFailure::Failed) => continue,
                r => return r,
            }
        }
        Err(QpFailure::Failed)
    }

    /// Whether the condensed Hessian admits a Cholesky factorisation.
    pub(super) fn boxqp_is_pd(&mut self) -> bool {
        self.boxqp.solve(&self.cond.hc, &self.cond.hv, &self.inf_lo, &self.inf_hi, 1e-12, 1).is_ok()
    }

    /// Merit `J + ν (Σ‖d‖₁ + ‖x0 − s_0‖₁ + state-bound violations)` at `(s + tΔs, u + tΔu)`;
    /// `None` when the dynamics fail there. With `reject_above`, the trial may stop as soon
    /// as the merit is known to exceed it and return a value above it (see [`Self::trial_at`]).
    pub(super) fn merit_at(&mut self, t: f64, reject_above: Option<f64>) -> Option<f64> {
        let (j, c) = self.trial_at(t, reject_above)?;
        let m = j + self.merit_nu * c;
        if m.is_finite() {
            Some(m)
        } else {
            None
        }
    }

    /// Cost `J` and ℓ1 constraint violation `θ = Σ‖d‖₁ + ‖x0 − s_0‖₁ + state-bound
    /// violations` at the trial point `(s + tΔs, u + tΔu)` (stored in the shift buffers, its
    /// `Φ` in `trial_phi`); `None` when the dynamics fail there. A trial needs only the
    /// states: the intervals are integrated without sensitivities (in the real-time
    /// iteration, the implicit midpoint rule's Newton iterations warm-started from the
    /// linearisation's converged substeps,
    /// [`Integrator::integrate_near`](crate::Integrator::integrate_near)); in parallel with
    /// [`crate::SqpSettings::parallel_intervals`] (the sums run in interval order either way,
    /// so the result is the same to the bit).
    ///
    /// `reject_above = Some(b)` (merit line search): the serial sweep stops after the first
    /// interval whose partial merit `J + ν θ_partial` exceeds `b` (the later terms of `θ` are
    /// non-negative and floating-point sums and products are monotone, so the full merit
    /// exceeds `b` too and the decision `merit ≤ b` is the same), returning that partial `θ`;
    /// `trial_phi` and the shift buffers then hold the trial only up to that interval.
    pub(super) fn trial_at(&mut self, t: f64, reject_above: Option<f64>) -> Option<(f64, f64)> {
        let n = self.n;
        self.trials += 1;
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
        let s = std::mem::take(&mut self.shift_s);
        let u = std::mem::take(&mut self.shift_u);
        let j = self.cost_of(&s, &u);
        self.shift_s = s;
        self.shift_u = u;
        let mut c = 0.0;
        for i in 0..self.nx {
            c += (self.x0[i] - self.shift_s[0][i]).abs();
        }
        let t0 = Instant::now();
        let ok = if self.integrators.len() == n && n > 1 {
            use rayon::prelude::*;
            let (model, s, u, counts) = (&self.model, &self.shift_s, &self.shift_u, &self.counts);
            let run = |k: usize,
                       int: &mut crate::Integrator,
                       phi: &mut nalgebra::DVector<f64>,
                       record: Option<&mut crate::MidpointRecord>| {
                let (s, u, phi) = (s[k].as_slice(), u[k].as_slice(), phi.as_mut_slice());
                int.set_substeps(counts[k]).is_ok()
                    && match record {
                        Some(r) => int.integrate_near(model, s, u, phi, r),
                        None => int.integrate(model, s, u, phi),
                    }
                    .is_ok()
            };
            let items =
                self.integrators.par_iter_mut().zip(self.trial_phi.par_iter_mut()).enumerate();
            let ok = if self.records.is_empty() {
                items.all(|(k, (int, phi))| run(k, int, phi, None))
            } else {
                items
                    .zip(self.records.par_iter_mut())
                    .all(|((k, (int, phi)), r)| run(k, int, phi, Some(r)))
            };
            if ok {
                for k in 0..n {
                    self.add_trial_violation(k, &mut c);
                }
            }
            ok
        } else {
            let mut ok = true;
            for k in 0..n {
                let int = &mut self.integrators[0];
                let (s, u) = (self.shift_s[k].as_slice(), self.shift_u[k].as_slice());
                let phi = self.trial_phi[k].as_mut_slice();
                if int.set_substeps(self.counts[k]).is_err()
                    || match self.records.get_mut(k) {
                        Some(r) => int.integrate_near(&self.model, s, u, phi, r),
                        None => int.integrate(&self.model, s, u, phi),
                    }
                    .is_err()
                {
                    ok = false;
                    break;
                }
                self.add_trial_violation(k, &mut c);
                if reject_above.is_some_and(|b| j + self.merit_nu * c > b) {
                    break;
                }
            }
            ok
        };
        self.stats.time_integration += t0.elapsed().as_secs_f64();
        if !ok {
            return None;
        }
        Some((j, c))
    }

    /// Adds interval `k`'s terms of the trial's violation `θ` to `c`: `‖Φ_k − s_{k+1}‖₁` and the
    /// state-bound violations of `s_{k+1}`.
    fn add_trial_violation(&self, k: usize, c: &mut f64) {
        for i in 0..self.nx {
            *c += (self.trial_phi[k][i] - self.shift_s[k + 1][i]).abs();
            *c += (self.ocp.x_min[i] - self.shift_s[k + 1][i]).max(0.0)
                + (self.shift_s[k + 1][i] - self.ocp.x_max[i]).max(0.0);
        }
    }

    /// Chooses the step length; `None` when the line search fails.
    pub(super) fn step_length(&mut self, first: bool) -> Option<f64> {
        match self.settings.globalisation {
            Globalisation::FullStep => Some(1.0),
            Globalisation::FixedRelaxation { alpha } => Some(alpha),
            Globalisation::Filter { backtracking, min_step, second_order_correction } => {
                self.filter_step_length(backtracking, min_step, second_order_correction, first)
            }
            Globalisation::MeritLineSearch {
                armijo,
                backtracking,
                min_step,
                adaptive_penalty,
                second_order_correction,
            } => {
                let n = self.n;
                let mut lam_max = 0.0_f64;
                for k in 0..=n {
                    lam_max = lam_max
                        .max(norm_inf(self.step.lam[k].as_slice()))
                        .max(norm_inf(self.step.mu[k].as_slice()));
                }
                if adaptive_penalty {
                    // Powell's rule: follows the multipliers down as well as up
                    let target = 1.1 * lam_max + 1e-12;
                    self.merit_nu = target.max(0.5 * (self.merit_nu + target));
                } else if self.merit_nu < 1.1 * lam_max {
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
                let bound = |t: f64| phi0 + armijo * t * dd + 1e-14 * phi0.abs();
                let accept = |phi: f64, t: f64| phi <= bound(t);
                let mut t = 1.0;
                // the second-order correction needs the whole rejected full-step trial
                let full = self
                    .merit_at(1.0, if second_order_correction { None } else { Some(bound(1.0)) });
                if let Some(phi) = full {
                    if accept(phi, 1.0) {
                        return Some(1.0);
                    }
                    if second_order_correction && self.second_order_correction() {
                        if let Some(phi) = self.merit_at(1.0, Some(bound(1.0))) {
                            if accept(phi, 1.0) {
                                self.stats.second_order_corrections += 1;
                                return Some(1.0);
                            }
                        }
                        self.step.copy_from(&self.step_saved);
                    }
                }
                loop {
                    t *= backtracking;
                    if t < min_step {
                        return None;
                    }
                    if let Some(phi) = self.merit_at(t, Some(bound(t))) {
                        if accept(phi, t) {
                            return Some(t);
                        }
                    }
                }
            }
        }
    }

    /// Second-order correction after a rejected full step (trial defects in `trial_phi`,
    /// trial nodes in `shift_s`): saves the step, solves the QP again with the defects
    /// `d_k + d_k(w + Δw)` (N&W (18.24): `∇c·p + c(w + Δw) − ∇c·Δw = 0` with `∇c·Δw = −c(w)`;
    /// the initial condition is linear and keeps its row) and leaves the corrected step in
    /// `self.step`. Returns `false` (step restored) when that QP fails.
    pub(super) fn second_order_correction(&mut self) -> bool {
        self.step_saved.copy_from(&self.step);
        for k in 0..self.n {
            self.d_saved[k].copy_from(&self.lin.d[k]);
            self.lin.d[k] += &self.trial_phi[k];
            self.lin.d[k] -= &self.shift_s[k + 1];
        }
        let r = self.solve_qp();
        for k in 0..self.n {
            self.lin.d[k].copy_from(&self.d_saved[k]);
        }
        match r {
            Ok(it) => {
                self.stats.qp_iterations += it;
                true
            }
            Err(_) => {
                self.step.copy_from(&self.step_saved);
                false
            }
        }
    }
}
