//! Linearisation at the iterate: substep counts, integrator sweeps with sensitivities,
//! Hessian blocks, gradients, bounds; the cost and the KKT residual.

use super::{HessianApproximation, SqpSolver};
use crate::dynamics::Dynamics;
use crate::error::Result;
use crate::la::{gemv, gemv_t, norm_inf};
use nalgebra::DVector;
use std::time::Instant;

impl<D: Dynamics> SqpSolver<D> {
    /// Chooses every interval's substep count from the current iterate (adaptive table:
    /// nodes `s_k`, `s_{k+1}` and control `u_k`). They stay fixed for the linearisation and
    /// the line search of an iteration, so `A_k`, `B_k` are the exact derivatives of the
    /// map whose defects are driven to zero. At the first iteration of a `solve` (`fresh`)
    /// they are chosen anew; at later ones a count may only grow (`max` with the new choice):
    /// a count that went down and up again would keep changing the map and stall the SQP
    /// (measured), while non-decreasing counts settle after finitely many changes and still
    /// meet the table at the final iterate.
    pub(super) fn choose_counts(&mut self, fresh: bool) {
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

    pub(super) fn integrator_calls(&self) -> usize {
        self.integrators.iter().map(|i| i.calls()).sum()
    }

    /// Linearises at the current iterate: `Φ`, `A`, `B`, defects, Hessian blocks, gradients, bounds.
    pub(super) fn linearise(&mut self, with_hessian: bool, fresh_counts: bool) -> Result<()> {
        let n = self.n;
        let exact = with_hessian && self.exact_now();
        let t0 = Instant::now();
        if self.lq.is_none() {
            self.choose_counts(fresh_counts);
            self.stats.mean_substeps =
                self.counts.iter().sum::<usize>() as f64 / self.n.max(1) as f64;
        }
        if self.settings.parallel_intervals && !exact && self.lq.is_none() {
            use rayon::prelude::*;
            let (model, s, u, counts) = (&self.model, &self.s, &self.u, &self.counts);
            let records = &mut self.records;
            let integrate =
                |k: usize,
                 int: &mut crate::Integrator,
                 phi: &mut nalgebra::DVector<f64>,
                 a: &mut nalgebra::DMatrix<f64>,
                 b: &mut nalgebra::DMatrix<f64>,
                 record: Option<&mut crate::MidpointRecord>| {
                    int.set_substeps(counts[k])?;
                    let (s, u, phi) = (s[k].as_slice(), u[k].as_slice(), phi.as_mut_slice());
                    match record {
                        Some(r) => {
                            int.integrate_with_sensitivities_recorded(model, s, u, phi, a, b, r)
                        }
                        None => int.integrate_with_sensitivities(model, s, u, phi, a, b),
                    }
                };
            let items = self
                .integrators
                .par_iter_mut()
                .zip(self.phi.par_iter_mut())
                .zip(self.lin.a.par_iter_mut())
                .zip(self.lin.b.par_iter_mut())
                .enumerate();
            if records.is_empty() {
                items
                    .try_for_each(|(k, (((int, phi), a), b))| integrate(k, int, phi, a, b, None))?;
            } else {
                items.zip(records.par_iter_mut()).try_for_each(
                    |((k, (((int, phi), a), b)), r)| integrate(k, int, phi, a, b, Some(r)),
                )?;
            }
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
            } else if let Some(record) = self.records.get_mut(k) {
                self.integrators[0].integrate_with_sensitivities_recorded(
                    &self.model,
                    self.s[k].as_slice(),
                    self.u[k].as_slice(),
                    self.phi[k].as_mut_slice(),
                    &mut self.lin.a[k],
                    &mut self.lin.b[k],
                    record,
                )?;
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
            // gradient q_k = w Q (s_k − x_r,k) (+ P (s_N − x_r,N))
            self.tmp_x.copy_from(&self.s[k]);
            self.tmp_x -= self.ocp.node_reference(k);
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
        if exact_blocks && self.settings.hessian == HessianApproximation::ExactProjected {
            self.project_stage_blocks();
        }
        self.lin.g0.copy_from(&self.x0);
        self.lin.g0 -= &self.s[0];
        self.stats.time_condensing += t1.elapsed().as_secs_f64();
        Ok(())
    }

    /// Cost `J` at `(s, u)`.
    pub(super) fn cost_of(&mut self, s: &[DVector<f64>], u: &[DVector<f64>]) -> f64 {
        let n = self.n;
        let dt = self.ocp.interval();
        let mut j = 0.0;
        for k in 0..=n {
            self.tmp_x.copy_from(&s[k]);
            self.tmp_x -= self.ocp.node_reference(k);
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
    pub(super) fn bound_violation(&self, s: &DVector<f64>) -> f64 {
        let mut v = 0.0_f64;
        for i in 0..self.nx {
            v = v.max(self.ocp.x_min[i] - s[i]).max(s[i] - self.ocp.x_max[i]);
        }
        v
    }

    /// KKT residual (max norm) and constraint violation at the current linearisation.
    pub(super) fn kkt(&mut self) -> (f64, f64) {
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
}
