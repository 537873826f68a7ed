//! Curvature beyond Gauss–Newton in the QP: convexification of the exact Lagrangian Hessian
//! (stage projection, inertia correction, Levenberg–Marquardt retries) and the structured
//! quasi-Newton estimate of the dynamics' curvature.

use super::{SqpSolver, PROJECTION_FLOOR};
use crate::dynamics::Dynamics;
use crate::qp::QpFailure;
use nalgebra::{DMatrix, DVector, SymmetricEigen};

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

/// The structured quasi-Newton estimates of
/// [`HessianApproximation::GaussNewtonThenQuasiNewton`](super::HessianApproximation::GaussNewtonThenQuasiNewton):
/// one block `M_k ≈ ∇²_{(s,u)}(λ_{k+1}ᵀΦ_k)` per interval and the previous iterate's
/// Jacobians and point.
#[derive(Clone, Debug)]
pub(super) struct QuasiNewton {
    m: Vec<DMatrix<f64>>,
    a_prev: Vec<DMatrix<f64>>,
    b_prev: Vec<DMatrix<f64>>,
    z_prev: Vec<DVector<f64>>,
    have_prev: bool,
    damped_bfgs: bool,
    /// `B_k = G_k + M_k` of the damped BFGS update and its Gauss–Newton part `G_k`.
    b: DMatrix<f64>,
    g: DMatrix<f64>,
    bs: DVector<f64>,
    s: DVector<f64>,
    y: DVector<f64>,
    r: DVector<f64>,
    /// Rank-one updates made and skipped in this solve.
    updates: usize,
    skipped: usize,
}

impl QuasiNewton {
    pub(super) fn new(n: usize, nx: usize, nu: usize, damped_bfgs: bool) -> Self {
        let nz = nx + nu;
        Self {
            m: vec![DMatrix::zeros(nz, nz); n],
            a_prev: vec![DMatrix::zeros(nx, nx); n],
            b_prev: vec![DMatrix::zeros(nx, nu); n],
            z_prev: vec![DVector::zeros(nz); n],
            have_prev: false,
            damped_bfgs,
            b: DMatrix::zeros(nz, nz),
            g: DMatrix::zeros(nz, nz),
            bs: DVector::zeros(nz),
            s: DVector::zeros(nz),
            y: DVector::zeros(nz),
            r: DVector::zeros(nz),
            updates: 0,
            skipped: 0,
        }
    }

    /// SR1 update of block `k` from `self.s`, `self.y` (N&W (6.24), skip rule (6.26)).
    fn sr1(&mut self, k: usize) {
        let m = &mut self.m[k];
        self.r.copy_from(&self.y);
        self.r.gemv(-1.0, m, &self.s, 1.0);
        let rs = self.r.dot(&self.s);
        let (rn, sn) = (self.r.norm(), self.s.norm());
        if !rs.is_finite() || rn == 0.0 || rs.abs() < 1e-8 * rn * sn {
            self.skipped += 1;
            return;
        }
        m.ger(1.0 / rs, &self.r, &self.r, 1.0);
        self.updates += 1;
    }

    /// Damped BFGS update of `B_k = G_k + M_k` (`G_k` in `self.b` on entry) from `self.s`
    /// and `self.y` (dynamics part; the cost part `G_k s` is added here), stored back as
    /// `M_k = B_k − G_k` (N&W Procedure 18.2).
    fn damped_bfgs(&mut self, k: usize) {
        self.g.copy_from(&self.b);
        self.b += &self.m[k];
        self.bs.gemv(1.0, &self.b, &self.s, 0.0);
        let sbs = self.s.dot(&self.bs);
        let ss = self.s.norm_squared();
        // y of the Lagrangian: dynamics part plus the exact cost curvature G s
        self.r.gemv(1.0, &self.g, &self.s, 0.0);
        self.r += &self.y;
        let sy = self.s.dot(&self.r);
        if !sbs.is_finite() || !sy.is_finite() || sbs <= 1e-14 * ss {
            self.skipped += 1;
            return;
        }
        let theta = if sy >= 0.2 * sbs { 1.0 } else { 0.8 * sbs / (sbs - sy) };
        self.r *= theta;
        self.r.axpy(1.0 - theta, &self.bs, 1.0);
        let sr = self.s.dot(&self.r);
        let m = &mut self.m[k];
        m.ger(-1.0 / sbs, &self.bs, &self.bs, 1.0);
        m.ger(1.0 / sr, &self.r, &self.r, 1.0);
        self.updates += 1;
    }
}

impl<D: Dynamics> SqpSolver<D> {
    /// After a linearisation: updates every `M_k` from the step since the previous one
    /// (none at the first iteration of a solve, `first`, which clears the estimates), keeps
    /// this iterate's Jacobians and point, and, after the switch, adds `M_k` to the stage
    /// blocks `[[Q_k, S_kᵀ], [S_k, R_k]]` of the QP.
    pub(super) fn quasi_newton_update(&mut self, first: bool) {
        let Some(mut qn) = self.qn.take() else { return };
        let (nx, nu) = (self.nx, self.nu);
        if first {
            for m in &mut qn.m {
                m.fill(0.0);
            }
            qn.have_prev = false;
            qn.updates = 0;
            qn.skipped = 0;
        }
        for k in 0..self.n {
            if qn.have_prev {
                for i in 0..nx {
                    qn.s[i] = self.s[k][i] - qn.z_prev[k][i];
                }
                for i in 0..nu {
                    qn.s[nx + i] = self.u[k][i] - qn.z_prev[k][nx + i];
                }
                if qn.s.iter().any(|v| *v != 0.0) {
                    let lam = &self.lam[k + 1];
                    let (mut yx, mut yu) = qn.y.rows_range_pair_mut(0..nx, nx..nx + nu);
                    yx.gemv_tr(1.0, &self.lin.a[k], lam, 0.0);
                    yx.gemv_tr(-1.0, &qn.a_prev[k], lam, 1.0);
                    yu.gemv_tr(1.0, &self.lin.b[k], lam, 0.0);
                    yu.gemv_tr(-1.0, &qn.b_prev[k], lam, 1.0);
                    if qn.damped_bfgs {
                        // the Gauss–Newton block of this linearisation (the cost's is constant)
                        qn.b.view_mut((0, 0), (nx, nx)).copy_from(&self.lin.hq[k]);
                        qn.b.view_mut((nx, nx), (nu, nu)).copy_from(&self.lin.hr[k]);
                        qn.b.view_mut((nx, 0), (nu, nx)).copy_from(&self.lin.hs[k]);
                        qn.b.view_mut((0, nx), (nx, nu)).tr_copy_from(&self.lin.hs[k]);
                        qn.damped_bfgs(k);
                    } else {
                        qn.sr1(k);
                    }
                }
            }
            qn.a_prev[k].copy_from(&self.lin.a[k]);
            qn.b_prev[k].copy_from(&self.lin.b[k]);
            qn.z_prev[k].rows_mut(0, nx).copy_from(&self.s[k]);
            qn.z_prev[k].rows_mut(nx, nu).copy_from(&self.u[k]);
            if self.exact_phase {
                let m = &qn.m[k];
                self.lin.hq[k] += m.view((0, 0), (nx, nx));
                self.lin.hr[k] += m.view((nx, nx), (nu, nu));
                self.lin.hs[k] += m.view((nx, 0), (nu, nx));
            }
        }
        qn.have_prev = true;
        self.stats.quasi_newton_updates = qn.updates;
        self.qn = Some(qn);
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
