//! The filter line search (Wächter & Biegler, *On the implementation of an interior-point
//! filter line-search algorithm*, Math. Program. 106, 2006, §2.3; the globalisation of IPOPT)
//! on the pair (cost `J`, ℓ1 constraint violation `θ`), with the second-order correction.
//!
//! A trial point `w + tΔw` is acceptable when it is not dominated by the filter (no entry
//! `(θ_j, J_j)` with `θ ≥ θ_j` and `J ≥ J_j`), `θ ≤ θ_max`, and
//!
//! * (f-type) when the step is a descent direction of `J` that dominates the violation,
//!   `m = ∇JᵀΔw < 0`, `t(−m)^{s_J} > δ θ^{s_θ}` and `θ ≤ θ_min`: Armijo on the cost alone,
//!   `J(t) ≤ J + η t m`;
//! * (h-type) otherwise: enough progress in one of the two, `θ(t) ≤ (1 − γ_θ)θ` or
//!   `J(t) ≤ J − γ_J θ`; the filter then gets the entry `((1 − γ_θ)θ, J − γ_J θ)`.
//!
//! Unlike the ℓ1 merit, the filter needs no penalty and accepts steps that trade a little
//! feasibility for cost (the Gauss–Newton steps along a curved constraint manifold that the
//! merit rejects). Constants are IPOPT's defaults.

use super::SqpSolver;
use crate::dynamics::Dynamics;

const GAMMA_THETA: f64 = 1e-5;
const GAMMA_J: f64 = 1e-8;
const DELTA: f64 = 1.0;
const S_THETA: f64 = 1.1;
const S_J: f64 = 2.3;
const ETA: f64 = 1e-8;

/// Filter state of one solve.
#[derive(Clone, Debug, Default)]
pub(super) struct Filter {
    entries: Vec<(f64, f64)>,
    theta_max: f64,
    theta_min: f64,
}

impl Filter {
    pub(super) fn with_capacity(n: usize) -> Self {
        Self { entries: Vec::with_capacity(n), theta_max: f64::INFINITY, theta_min: 0.0 }
    }

    /// Empties the filter and sets `θ_max = 10⁴ max(1, θ0)`, `θ_min = 10⁻⁴ max(1, θ0)`.
    pub(super) fn reset(&mut self, theta0: f64) {
        self.entries.clear();
        self.theta_max = 1e4 * theta0.max(1.0);
        self.theta_min = 1e-4 * theta0.max(1.0);
    }

    fn dominated(&self, theta: f64, j: f64) -> bool {
        theta > self.theta_max || self.entries.iter().any(|&(tj, jj)| theta >= tj && j >= jj)
    }
}

/// Current point of a filter line search.
#[derive(Clone, Copy)]
struct Point {
    j: f64,
    theta: f64,
    /// `∇JᵀΔw`.
    m: f64,
}

impl Point {
    /// Whether `t` is an f-type (cost-decrease) step.
    fn f_type(&self, filter: &Filter, t: f64) -> bool {
        self.m < 0.0
            && t * (-self.m).powf(S_J) > DELTA * self.theta.powf(S_THETA)
            && self.theta <= filter.theta_min
    }

    /// Acceptability of the trial `(j, theta)` at step `t`.
    fn accepts(&self, filter: &Filter, t: f64, j: f64, theta: f64) -> bool {
        if !(j.is_finite() && theta.is_finite()) || filter.dominated(theta, j) {
            return false;
        }
        if self.f_type(filter, t) {
            j <= self.j + ETA * t * self.m + 1e-14 * self.j.abs()
        } else {
            theta <= (1.0 - GAMMA_THETA) * self.theta || j <= self.j - GAMMA_J * self.theta
        }
    }
}

impl<D: Dynamics> SqpSolver<D> {
    /// Filter line search on the step in `self.step`: the step length, or `None` when `t`
    /// falls below `min_step` (status [`crate::SqpStatus::LineSearchFailed`]).
    pub(super) fn filter_step_length(
        &mut self,
        backtracking: f64,
        min_step: f64,
        second_order_correction: bool,
        first: bool,
    ) -> Option<f64> {
        let n = self.n;
        let mut m = 0.0;
        for k in 0..=n {
            m += self.lin.q[k].dot(&self.step.ds[k]);
            if k < n {
                m += self.lin.r[k].dot(&self.step.du[k]);
            }
        }
        let mut theta = self.lin.g0.lp_norm(1);
        for k in 0..n {
            theta += self.lin.d[k].lp_norm(1);
            for i in 0..self.nx {
                let s = self.s[k + 1][i];
                theta += (self.ocp.x_min[i] - s).max(0.0) + (s - self.ocp.x_max[i]).max(0.0);
            }
        }
        let s_ref = std::mem::take(&mut self.s);
        let u_ref = std::mem::take(&mut self.u);
        let j = self.cost_of(&s_ref, &u_ref);
        self.s = s_ref;
        self.u = u_ref;
        if first {
            self.filter.reset(theta);
        }
        let p = Point { j, theta, m };
        let mut t = 1.0;
        loop {
            if let Some((jt, tht)) = self.trial_at(t, None) {
                if p.accepts(&self.filter, t, jt, tht) {
                    self.augment(&p, t);
                    return Some(t);
                }
                if t == 1.0
                    && second_order_correction
                    && tht >= theta
                    && self.second_order_correction()
                {
                    if let Some((js, ths)) = self.trial_at(1.0, None) {
                        if p.accepts(&self.filter, 1.0, js, ths) {
                            self.stats.second_order_corrections += 1;
                            self.augment(&p, 1.0);
                            return Some(1.0);
                        }
                    }
                    self.step.copy_from(&self.step_saved);
                }
            }
            t *= backtracking;
            if t < min_step {
                return None;
            }
        }
    }

    /// Adds the current point's entry to the filter after an h-type step.
    fn augment(&mut self, p: &Point, t: f64) {
        if !p.f_type(&self.filter, t) {
            self.filter.entries.push(((1.0 - GAMMA_THETA) * p.theta, p.j - GAMMA_J * p.theta));
        }
    }
}
