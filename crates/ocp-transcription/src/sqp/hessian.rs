//! Convexification of the exact Lagrangian Hessian stage by stage
//! ([`HessianApproximation::ExactProjected`](super::HessianApproximation::ExactProjected)).

use super::{SqpSolver, PROJECTION_FLOOR};
use crate::dynamics::Dynamics;
use crate::qp::QpFailure;
use nalgebra::{DMatrix, SymmetricEigen};

/// Projects the symmetric `m` onto `{H : H ⪰ εI}`: with `m = VΛVᵀ`,
/// `m ← V max(Λ, ε) Vᵀ`, `ε = PROJECTION_FLOOR · max(1, max|Λ|)` (the nearest matrix in the
/// Frobenius norm with eigenvalues ≥ ε). Returns whether an eigenvalue was clipped; a block
/// whose eigenvalues are all ≥ ε is left as it was, bit for bit.
pub(crate) fn project_block(m: &mut DMatrix<f64>) -> bool {
    let eig = SymmetricEigen::new(m.clone());
    let scale = eig.eigenvalues.iter().fold(1.0_f64, |a, v| a.max(v.abs()));
    let eps = PROJECTION_FLOOR * scale;
    if eig.eigenvalues.iter().all(|&v| v >= eps) {
        return false;
    }
    let mut vl = eig.eigenvectors.clone();
    for (j, &v) in eig.eigenvalues.iter().enumerate() {
        let l = v.max(eps);
        vl.column_mut(j).scale_mut(l);
    }
    let p = &vl * eig.eigenvectors.transpose();
    let n = m.nrows();
    for c in 0..n {
        for r in 0..n {
            m[(r, c)] = 0.5 * (p[(r, c)] + p[(c, r)]);
        }
    }
    true
}

impl<D: Dynamics> SqpSolver<D> {
    /// Projects every stage block `[[Q_k, S_kᵀ], [S_k, R_k]]` of the linearisation (cost,
    /// Levenberg–Marquardt term and `λ_{k+1}ᵀ∇²Φ_k` already summed) and the terminal block
    /// `Q_N` with [`project_block`]; counts the clipped blocks in `regularisations`.
    pub(super) fn project_stage_blocks(&mut self) {
        let (nx, nu) = (self.nx, self.nu);
        let nz = nx + nu;
        let mut m = DMatrix::zeros(nz, nz);
        for k in 0..self.n {
            m.view_mut((0, 0), (nx, nx)).copy_from(&self.lin.hq[k]);
            m.view_mut((nx, nx), (nu, nu)).copy_from(&self.lin.hr[k]);
            m.view_mut((nx, 0), (nu, nx)).copy_from(&self.lin.hs[k]);
            m.view_mut((0, nx), (nx, nu)).copy_from(&self.lin.hs[k].transpose());
            if project_block(&mut m) {
                self.stats.regularisations += 1;
                self.lin.hq[k].copy_from(&m.view((0, 0), (nx, nx)));
                self.lin.hr[k].copy_from(&m.view((nx, nx), (nu, nu)));
                self.lin.hs[k].copy_from(&m.view((nx, 0), (nu, nx)));
            }
        }
        let mut q = self.lin.hq[self.n].clone();
        if project_block(&mut q) {
            self.stats.regularisations += 1;
            self.lin.hq[self.n].copy_from(&q);
        }
    }
}

impl<D: Dynamics> SqpSolver<D> {
    /// Replaces the Hessian blocks by the Gauss–Newton ones (the cost Hessian (34) and the
    /// Levenberg–Marquardt term): `Q_k = c_kΔt Q + μI (+ P at k = N)`, `R_k = Δt R + μI`,
    /// `S_k = 0`, as [`SqpSolver::linearise`] forms them without the exact Hessian.
    pub(super) fn gauss_newton_blocks(&mut self) {
        let dt = self.ocp.interval();
        let lm = self.settings.levenberg_marquardt;
        for k in 0..=self.n {
            self.lin.hq[k].fill(0.0);
            crate::la::axpy(
                self.lin.hq[k].as_mut_slice(),
                self.ocp.node_weight(k),
                self.ocp.q.as_slice(),
            );
            if k == self.n {
                self.lin.hq[k] += &self.ocp.terminal;
            }
            for i in 0..self.nx {
                self.lin.hq[k][(i, i)] += lm;
            }
            if k < self.n {
                self.lin.hr[k].fill(0.0);
                self.lin.hs[k].fill(0.0);
                crate::la::axpy(self.lin.hr[k].as_mut_slice(), dt, self.ocp.r.as_slice());
                for i in 0..self.nu {
                    self.lin.hr[k][(i, i)] += lm;
                }
            }
        }
    }
}

impl<D: Dynamics> SqpSolver<D> {
    /// Inertia correction of the exact Hessian in the full space (the rule of IPOPT,
    /// Wächter & Biegler 2006, §3.1, Algorithm IC): when the condensed Hessian `H_c` is not
    /// positive definite on the controls not at a bound ([`Self::free_part_is_pd`]), `δI` is
    /// added to every block `Q_k`, `R_k` and `H_c` is formed again,
    /// with `δ = max(δ_min, δ_last/3)` first (`δ = δ₀ = 1e-4·(1 + c)` when no shift was
    /// needed before in this solve, `c` the largest diagonal entry of the cost Hessian), then
    /// `δ ← 8δ` (`100δ` without a previous shift) until a Cholesky factorisation succeeds.
    /// A shift of all of `(s, u)` rather than of the reduced (control) Hessian alone is a
    /// Levenberg–Marquardt step in the NLP variables: it bounds the state excursion of the
    /// step too, where a shift of the reduced Hessian just above its smallest eigenvalue gives
    /// long steps along directions of almost zero curvature. Returns `false` when 30 shifts
    /// fail (the blocks are left shifted; the caller falls back to Gauss–Newton).
    pub(super) fn inertia_correction(&mut self) -> bool {
        if self.free_part_is_pd() {
            return true;
        }
        let mut c = 0.0_f64;
        for k in 0..=self.n {
            c = c.max(self.ocp.node_weight(k) * self.ocp.q.diagonal().max());
        }
        c = c.max(self.ocp.interval() * self.ocp.r.diagonal().max());
        let delta_min = 1e-12 * (1.0 + c);
        let first = self.inertia_delta == 0.0;
        let mut delta =
            if first { 1e-4 * (1.0 + c) } else { (self.inertia_delta / 3.0).max(delta_min) };
        let mut added = 0.0;
        for _ in 0..30 {
            self.shift_blocks(delta - added);
            added = delta;
            self.stats.regularisations += 1;
            let t = std::time::Instant::now();
            self.cond.condense(&self.lin);
            self.stats.time_condensing += t.elapsed().as_secs_f64();
            if self.free_part_is_pd() {
                self.inertia_delta = delta;
                self.applied_delta = delta;
                return true;
            }
            delta *= if first { 100.0 } else { 8.0 };
        }
        false
    }

    /// The scale `δ₀ = 1e-4·(1 + c)` of the first shift (see [`Self::inertia_correction`]).
    fn first_shift(&self) -> f64 {
        let mut c = 0.0_f64;
        for k in 0..=self.n {
            c = c.max(self.ocp.node_weight(k) * self.ocp.q.diagonal().max());
        }
        c = c.max(self.ocp.interval() * self.ocp.r.diagonal().max());
        1e-4 * (1.0 + c)
    }

    /// Step length of an exact-Hessian iteration whose QP step was not accepted in full, or of
    /// a Gauss–Newton iteration whose line search failed (`t` from the line search): the step
    /// is a poor model of the problem along its direction, so instead of a short step along it
    /// the shift is raised,
    /// `δ ← max(10δ, δ₀)`, and the QP solved again (a Levenberg–Marquardt step, which turns
    /// towards the steepest descent of the Lagrangian as `δ` grows), up to eight times, until
    /// the full step is accepted; the last line-search result otherwise. The shift is
    /// remembered for the next iteration's inertia correction.
    pub(super) fn levenberg_marquardt_retries(
        &mut self,
        first: bool,
        mut t: Option<f64>,
    ) -> Result<Option<f64>, QpFailure> {
        let d0 = self.first_shift();
        for _ in 0..8 {
            if t == Some(1.0) {
                break;
            }
            let delta = (10.0 * self.applied_delta).max(d0);
            self.shift_blocks(delta - self.applied_delta);
            self.applied_delta = delta;
            self.inertia_delta = self.inertia_delta.max(delta);
            self.stats.regularisations += 1;
            self.stats.qp_iterations += self.solve_qp()?;
            t = self.step_length(first);
        }
        Ok(t)
    }

    /// Whether the condensed Hessian is positive definite on the controls that are not at a
    /// bound at the iterate (the curvature along an active bound does not enter the
    /// second-order condition; at a solution with active bounds the full condensed Hessian
    /// may be indefinite while the step is a Newton step).
    fn free_part_is_pd(&mut self) -> bool {
        let m = self.cond.hc.nrows();
        let mut h = self.cond.hc.clone();
        for k in 0..self.n {
            for i in 0..self.nu {
                let (u, lo, hi) = (self.u[k][i], self.ocp.u_min[i], self.ocp.u_max[i]);
                let tol = 1e-10 * (1.0 + u.abs());
                if u - lo <= tol || hi - u <= tol {
                    let j = k * self.nu + i;
                    for r in 0..m {
                        h[(r, j)] = 0.0;
                        h[(j, r)] = 0.0;
                    }
                    h[(j, j)] = 1.0;
                }
            }
        }
        h.cholesky().is_some()
    }

    /// Adds `d` to the diagonals of every `Q_k` and `R_k`.
    fn shift_blocks(&mut self, d: f64) {
        for k in 0..=self.n {
            for i in 0..self.nx {
                self.lin.hq[k][(i, i)] += d;
            }
            if k < self.n {
                for i in 0..self.nu {
                    self.lin.hr[k][(i, i)] += d;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_clips_negative_eigenvalues_and_keeps_definite_blocks() {
        let mut a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]); // eigenvalues 3, −1
        assert!(project_block(&mut a));
        let e = SymmetricEigen::new(a.clone()).eigenvalues;
        let (lo, hi) = (e.min(), e.max());
        assert!((hi - 3.0).abs() < 1e-12 && (lo - 3.0 * PROJECTION_FLOOR).abs() < 1e-12);
        let b0 = DMatrix::from_row_slice(2, 2, &[2.0, 0.5, 0.5, 1.0]);
        let mut b = b0.clone();
        assert!(!project_block(&mut b));
        assert_eq!(b, b0);
    }
}
