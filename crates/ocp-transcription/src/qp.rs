//! QP subproblems of the SQP: linearisation data, condensing, a dense interior-point solver
//! for bounds-only QPs (faer Cholesky), and Clarabel in condensed and sparse form.

use crate::la::{fmut, fref, gemv, gemv_t, norm_inf};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::{factor as llt_factor, solve as llt_solve};
use faer::linalg::matmul::matmul;
use faer::{Accum, Conj, Par};
use nalgebra::{DMatrix, DVector};

/// How the QP subproblem is formed and solved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum QpForm {
    /// Condensed; the dense interior-point solver when only control bounds are present,
    /// Clarabel otherwise; the sparse multiple-shooting QP when the condensed Hessian's
    /// condition estimate exceeds [`crate::AUTO_SPARSE_CONDITION`] or it has no Cholesky
    /// factor (semidefinite Hessian blocks). The default.
    Auto,
    /// Condensed, dense primal–dual interior point on box constraints (faer Cholesky).
    /// With state bounds it falls back to [`QpForm::CondensedClarabel`].
    CondensedDense,
    /// Condensed, Clarabel (dense upper-triangular `P`, state bounds as rows of `G`).
    CondensedClarabel,
    /// Multiple-shooting (uncondensed) sparse QP, Clarabel; no condensing, better
    /// conditioned for unstable or chaotic dynamics.
    SparseClarabel,
}

/// The linearised problem at an SQP iterate (all blocks overwritten in place).
#[derive(Clone, Debug)]
pub(crate) struct Linearisation {
    pub a: Vec<DMatrix<f64>>,
    pub b: Vec<DMatrix<f64>>,
    /// Defects `d_k = Φ(s_k, u_k) − s_{k+1}`.
    pub d: Vec<DVector<f64>>,
    /// Initial-value residual `g_0 = x0 − s_0` (the fixed `Δs_0`).
    pub g0: DVector<f64>,
    /// Hessian blocks: `hq[k]` (`nx²`, k = 0..=N), `hr[k]` (`nu²`), `hs[k]` (`nu × nx`).
    pub hq: Vec<DMatrix<f64>>,
    pub hr: Vec<DMatrix<f64>>,
    pub hs: Vec<DMatrix<f64>>,
    /// Cost gradients.
    pub q: Vec<DVector<f64>>,
    pub r: Vec<DVector<f64>>,
    /// Step bounds.
    pub du_lo: Vec<DVector<f64>>,
    pub du_hi: Vec<DVector<f64>>,
    pub dx_lo: Vec<DVector<f64>>,
    pub dx_hi: Vec<DVector<f64>>,
}

impl Linearisation {
    pub(crate) fn new(n: usize, nx: usize, nu: usize) -> Self {
        Self {
            a: vec![DMatrix::zeros(nx, nx); n],
            b: vec![DMatrix::zeros(nx, nu); n],
            d: vec![DVector::zeros(nx); n],
            g0: DVector::zeros(nx),
            hq: vec![DMatrix::zeros(nx, nx); n + 1],
            hr: vec![DMatrix::zeros(nu, nu); n],
            hs: vec![DMatrix::zeros(nu, nx); n],
            q: vec![DVector::zeros(nx); n + 1],
            r: vec![DVector::zeros(nu); n],
            du_lo: vec![DVector::zeros(nu); n],
            du_hi: vec![DVector::zeros(nu); n],
            dx_lo: vec![DVector::zeros(nx); n + 1],
            dx_hi: vec![DVector::zeros(nx); n + 1],
        }
    }
}

/// The QP step: `Δs_k`, `Δu_k`, and the QP multipliers `λ_k` of `s_{k+1} = Φ(s_k, u_k)`
/// (`lam[k+1]`) and of the initial condition (`lam[0]`).
#[derive(Clone, Debug)]
pub(crate) struct Step {
    pub ds: Vec<DVector<f64>>,
    pub du: Vec<DVector<f64>>,
    pub lam: Vec<DVector<f64>>,
    /// State-bound multipliers (upper minus lower) per node.
    pub mu: Vec<DVector<f64>>,
}

impl Step {
    pub(crate) fn new(n: usize, nx: usize, nu: usize) -> Self {
        Self {
            ds: vec![DVector::zeros(nx); n + 1],
            du: vec![DVector::zeros(nu); n],
            lam: vec![DVector::zeros(nx); n + 1],
            mu: vec![DVector::zeros(nx); n + 1],
        }
    }

    /// Copies `other` into `self` (same dimensions; no allocation).
    pub(crate) fn copy_from(&mut self, other: &Step) {
        for (a, b) in [(&mut self.ds, &other.ds), (&mut self.du, &other.du)]
            .into_iter()
            .chain([(&mut self.lam, &other.lam), (&mut self.mu, &other.mu)])
        {
            for (x, y) in a.iter_mut().zip(b) {
                x.copy_from(y);
            }
        }
    }
}

/// Why a QP did not give a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum QpFailure {
    Infeasible,
    Failed,
}

/// Dense condensing workspace (`Δs = G Δu + g`).
pub(crate) struct Condenser {
    n: usize,
    nx: usize,
    nu: usize,
    /// `G`, `N nx × N nu`; block row `k−1` holds `∂Δs_k/∂Δu`.
    pub gmat: DMatrix<f64>,
    /// Affine parts `g_k`, k = 0..=N.
    pub gaff: Vec<DVector<f64>>,
    tmp: DMatrix<f64>,
    p: DMatrix<f64>,
    pa: DMatrix<f64>,
    pb: DMatrix<f64>,
    m: DMatrix<f64>,
    rho: DVector<f64>,
    rho2: DVector<f64>,
    /// Condensed Hessian `N nu × N nu` (full, symmetric).
    pub hc: DMatrix<f64>,
    /// Condensed gradient.
    pub hv: DVector<f64>,
    /// Condensed box bounds.
    pub lo: DVector<f64>,
    pub hi: DVector<f64>,
}

impl Condenser {
    pub(crate) fn new(n: usize, nx: usize, nu: usize) -> Self {
        Self {
            n,
            nx,
            nu,
            gmat: DMatrix::zeros(n * nx, n * nu),
            gaff: vec![DVector::zeros(nx); n + 1],
            tmp: DMatrix::zeros(nx, n * nu),
            p: DMatrix::zeros(nx, nx),
            pa: DMatrix::zeros(nx, nx),
            pb: DMatrix::zeros(nx, nu),
            m: DMatrix::zeros(nx, nu),
            rho: DVector::zeros(nx),
            rho2: DVector::zeros(nx),
            hc: DMatrix::zeros(n * nu, n * nu),
            hv: DVector::zeros(n * nu),
            lo: DVector::zeros(n * nu),
            hi: DVector::zeros(n * nu),
        }
    }

    /// Builds `G`, `g`, `H_c`, `h` and the box bounds from the linearisation.
    pub(crate) fn condense(&mut self, lin: &Linearisation) {
        let (n, nx, nu) = (self.n, self.nx, self.nu);
        // affine parts
        self.gaff[0].copy_from(&lin.g0);
        for k in 0..n {
            let (head, tail) = self.gaff.split_at_mut(k + 1);
            gemv(tail[0].as_mut_slice(), &lin.a[k], head[k].as_slice(), 1.0, false);
            tail[0] += &lin.d[k];
        }
        // G, block row by block row
        self.gmat.fill(0.0);
        for k in 0..n {
            if k > 0 {
                let cols = k * nu;
                matmul(
                    fmut(&mut self.tmp).submatrix_mut(0, 0, nx, cols),
                    Accum::Replace,
                    fref(&lin.a[k]),
                    fref(&self.gmat).submatrix((k - 1) * nx, 0, nx, cols),
                    1.0,
                    Par::Seq,
                );
                self.gmat
                    .view_mut((k * nx, 0), (nx, cols))
                    .copy_from(&self.tmp.view((0, 0), (nx, cols)));
            }
            self.gmat.view_mut((k * nx, k * nu), (nx, nu)).copy_from(&lin.b[k]);
        }
        // backward recursion: P, ρ, H_c, h
        self.p.copy_from(&lin.hq[n]);
        gemv(self.rho.as_mut_slice(), &lin.hq[n], self.gaff[n].as_slice(), 1.0, false);
        self.rho += &lin.q[n];
        for j in (0..n).rev() {
            crate::la::gemm(&mut self.pb, &self.p, &lin.b[j], 1.0, false);
            crate::la::gemm_tn(&mut self.m, &lin.a[j], &self.pb, 1.0, false);
            for c in 0..nu {
                for r in 0..nx {
                    self.m[(r, c)] += lin.hs[j][(c, r)];
                }
            }
            // diagonal block
            {
                let mut hjj = self.hc.view_mut((j * nu, j * nu), (nu, nu));
                hjj.copy_from(&lin.hr[j]);
            }
            matmul(
                fmut(&mut self.hc).submatrix_mut(j * nu, j * nu, nu, nu),
                Accum::Add,
                fref(&lin.b[j]).transpose(),
                fref(&self.pb),
                1.0,
                Par::Seq,
            );
            // off-diagonal blocks H[i][j] = G_{j,i}ᵀ M_j, i < j
            if j > 0 {
                matmul(
                    fmut(&mut self.hc).submatrix_mut(0, j * nu, j * nu, nu),
                    Accum::Replace,
                    fref(&self.gmat).submatrix((j - 1) * nx, 0, nx, j * nu).transpose(),
                    fref(&self.m),
                    1.0,
                    Par::Seq,
                );
            }
            // gradient h_j = r_j + S_j g_j + B_jᵀ ρ_{j+1}
            {
                let hj = &mut self.hv.as_mut_slice()[j * nu..(j + 1) * nu];
                hj.copy_from_slice(lin.r[j].as_slice());
                gemv(hj, &lin.hs[j], self.gaff[j].as_slice(), 1.0, true);
                gemv_t(hj, &lin.b[j], self.rho.as_slice(), 1.0, true);
            }
            if j > 0 {
                // ρ_j = Q_j g_j + q_j + A_jᵀ ρ_{j+1};  P_j = Q_j + A_jᵀ P_{j+1} A_j
                gemv(self.rho2.as_mut_slice(), &lin.hq[j], self.gaff[j].as_slice(), 1.0, false);
                self.rho2 += &lin.q[j];
                gemv_t(self.rho2.as_mut_slice(), &lin.a[j], self.rho.as_slice(), 1.0, true);
                std::mem::swap(&mut self.rho, &mut self.rho2);
                crate::la::gemm(&mut self.pa, &self.p, &lin.a[j], 1.0, false);
                self.p.copy_from(&lin.hq[j]);
                crate::la::gemm_tn(&mut self.p, &lin.a[j], &self.pa, 1.0, true);
            }
        }
        // mirror the upper triangle
        let m = n * nu;
        for c in 0..m {
            for r in (c + 1)..m {
                self.hc[(r, c)] = self.hc[(c, r)];
            }
        }
        for k in 0..n {
            self.lo.rows_mut(k * nu, nu).copy_from(&lin.du_lo[k]);
            self.hi.rows_mut(k * nu, nu).copy_from(&lin.du_hi[k]);
        }
    }

    /// Recovers `Δs` and the multipliers from `Δu` (in `step.du`) and state-bound
    /// multipliers (in `step.mu`).
    pub(crate) fn expand(&self, lin: &Linearisation, du: &DVector<f64>, step: &mut Step) {
        let (n, nu) = (self.n, self.nu);
        for k in 0..n {
            step.du[k].copy_from(&du.rows(k * nu, nu));
        }
        expand_states(lin, step);
        debug_assert_eq!(step.du.len(), n);
    }
}

/// Forward `Δs_{k+1} = A_kΔs_k + B_kΔu_k + d_k` and backward multipliers
/// `λ_k = Q_kΔs_k + S_kᵀΔu_k + q_k + A_kᵀλ_{k+1} + μ_k`.
pub(crate) fn expand_states(lin: &Linearisation, step: &mut Step) {
    let n = step.du.len();
    step.ds[0].copy_from(&lin.g0);
    for k in 0..n {
        let (head, tail) = step.ds.split_at_mut(k + 1);
        gemv(tail[0].as_mut_slice(), &lin.a[k], head[k].as_slice(), 1.0, false);
        gemv(tail[0].as_mut_slice(), &lin.b[k], step.du[k].as_slice(), 1.0, true);
        tail[0] += &lin.d[k];
    }
    multipliers(lin, step);
}

/// Backward multiplier recursion from `Δs`, `Δu`, `μ`.
pub(crate) fn multipliers(lin: &Linearisation, step: &mut Step) {
    let n = step.du.len();
    {
        let lam = &mut step.lam[n];
        gemv(lam.as_mut_slice(), &lin.hq[n], step.ds[n].as_slice(), 1.0, false);
        *lam += &lin.q[n];
        *lam += &step.mu[n];
    }
    for k in (0..n).rev() {
        let (head, tail) = step.lam.split_at_mut(k + 1);
        let lam = &mut head[k];
        gemv(lam.as_mut_slice(), &lin.hq[k], step.ds[k].as_slice(), 1.0, false);
        gemv_t(lam.as_mut_slice(), &lin.hs[k], step.du[k].as_slice(), 1.0, true);
        gemv_t(lam.as_mut_slice(), &lin.a[k], tail[0].as_slice(), 1.0, true);
        *lam += &lin.q[k];
        *lam += &step.mu[k];
    }
}

/// Dense primal–dual interior point (Mehrotra predictor–corrector) for
/// `min ½xᵀHx + hᵀx` s.t. `lo ≤ x ≤ hi` (infinite bounds allowed), one faer Cholesky of
/// `H + diag(z/s)` per iteration. Workspace allocated once.
pub(crate) struct BoxQp {
    n: usize,
    k: DMatrix<f64>,
    x: DVector<f64>,
    sl: DVector<f64>,
    su: DVector<f64>,
    zl: DVector<f64>,
    zu: DVector<f64>,
    rd: DVector<f64>,
    dx: DVector<f64>,
    dzl: DVector<f64>,
    dzu: DVector<f64>,
    rhs: DVector<f64>,
    mem: MemBuffer,
}

impl BoxQp {
    pub(crate) fn new(n: usize) -> Self {
        let req = StackReq::any_of(&[
            llt_factor::cholesky_in_place_scratch::<f64>(n, Par::Seq, Default::default()),
            llt_solve::solve_in_place_scratch::<f64>(n, 1, Par::Seq),
        ]);
        let z = || DVector::zeros(n);
        Self {
            n,
            k: DMatrix::zeros(n, n),
            x: z(),
            sl: z(),
            su: z(),
            zl: z(),
            zu: z(),
            rd: z(),
            dx: z(),
            dzl: z(),
            dzu: z(),
            rhs: z(),
            mem: MemBuffer::new(req),
        }
    }

    /// `(max Lᵢᵢ / min Lᵢᵢ)²` of the Cholesky factor of `h` (a lower bound on its condition
    /// number); `∞` when `h` is not positive definite.
    pub(crate) fn condition_estimate(&mut self, h: &DMatrix<f64>) -> f64 {
        for i in 0..self.n {
            self.sl[i] = f64::INFINITY;
            self.su[i] = f64::INFINITY;
        }
        if !self.factor(h) {
            return f64::INFINITY;
        }
        let (mut lo, mut hi) = (f64::INFINITY, 0.0_f64);
        for i in 0..self.n {
            let d = self.k[(i, i)].abs();
            lo = lo.min(d);
            hi = hi.max(d);
        }
        if lo > 0.0 {
            (hi / lo).powi(2)
        } else {
            f64::INFINITY
        }
    }

    /// The primal solution of the last solve.
    pub(crate) fn solution(&self) -> &DVector<f64> {
        &self.x
    }

    fn factor(&mut self, h: &DMatrix<f64>) -> bool {
        for c in 0..self.n {
            for r in c..self.n {
                self.k[(r, c)] = h[(r, c)];
            }
            let d = (if self.lo_active(c) { self.zl[c] / self.sl[c] } else { 0.0 })
                + (if self.hi_active(c) { self.zu[c] / self.su[c] } else { 0.0 });
            self.k[(c, c)] += d;
        }
        llt_factor::cholesky_in_place(
            fmut(&mut self.k),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut self.mem),
            Default::default(),
        )
        .is_ok()
    }

    fn lo_active(&self, i: usize) -> bool {
        self.sl[i].is_finite()
    }
    fn hi_active(&self, i: usize) -> bool {
        self.su[i].is_finite()
    }

    fn solve_k(&mut self) {
        let n = self.n;
        llt_solve::solve_in_place_with_conj(
            fref(&self.k),
            Conj::No,
            faer::MatMut::from_column_major_slice_mut(self.rhs.as_mut_slice(), n, 1),
            Par::Seq,
            MemStack::new(&mut self.mem),
        );
        self.dx.copy_from(&self.rhs);
    }

    /// Solves; returns the iteration count.
    pub(crate) fn solve(
        &mut self,
        h: &DMatrix<f64>,
        g: &DVector<f64>,
        lo: &DVector<f64>,
        hi: &DVector<f64>,
        tol: f64,
        max_iter: usize,
    ) -> Result<usize, QpFailure> {
        let n = self.n;
        let mut m = 0usize;
        for i in 0..n {
            let (l, u) = (lo[i], hi[i]);
            if l.is_finite() && u.is_finite() && u - l <= 0.0 {
                return Err(QpFailure::Failed);
            }
            let x = if l.is_finite() && u.is_finite() {
                let th = (0.25 * (u - l)).min(1.0);
                0.0_f64.clamp(l + th, u - th)
            } else if l.is_finite() {
                0.0_f64.max(l + 1.0)
            } else if u.is_finite() {
                0.0_f64.min(u - 1.0)
            } else {
                0.0
            };
            self.x[i] = x;
            self.sl[i] = if l.is_finite() { x - l } else { f64::INFINITY };
            self.su[i] = if u.is_finite() { u - x } else { f64::INFINITY };
            self.zl[i] = if l.is_finite() { 1.0 } else { 0.0 };
            self.zu[i] = if u.is_finite() { 1.0 } else { 0.0 };
            m += l.is_finite() as usize + u.is_finite() as usize;
        }
        let gnorm = norm_inf(g.as_slice());
        if m == 0 {
            if !self.factor(h) {
                return Err(QpFailure::Failed);
            }
            self.rhs.copy_from(g);
            self.rhs *= -1.0;
            self.solve_k();
            self.x.copy_from(&self.dx);
            return if crate::la::all_finite(self.x.as_slice()) {
                Ok(1)
            } else {
                Err(QpFailure::Failed)
            };
        }
        for it in 1..=max_iter {
            // residual and complementarity
            gemv(self.rd.as_mut_slice(), h, self.x.as_slice(), 1.0, false);
            self.rd += g;
            let mut mu = 0.0;
            for i in 0..n {
                self.rd[i] += -self.zl[i] + self.zu[i];
                if self.lo_active(i) {
                    mu += self.sl[i] * self.zl[i];
                }
                if self.hi_active(i) {
                    mu += self.su[i] * self.zu[i];
                }
            }
            mu /= m as f64;
            let rnorm = norm_inf(self.rd.as_slice());
            if !(rnorm.is_finite() && mu.is_finite()) {
                return Err(QpFailure::Failed);
            }
            if rnorm <= tol * (1.0 + gnorm) && mu <= tol {
                return Ok(it);
            }
            if !self.factor(h) {
                return Err(QpFailure::Failed);
            }
            // predictor
            for i in 0..n {
                self.rhs[i] = -self.rd[i] - self.zl[i] + self.zu[i];
            }
            self.solve_k();
            self.dual_dirs(0.0, None);
            let alpha = self.step_length();
            let mut mu_aff = 0.0;
            for i in 0..n {
                if self.lo_active(i) {
                    mu_aff +=
                        (self.sl[i] + alpha * self.dx[i]) * (self.zl[i] + alpha * self.dzl[i]);
                }
                if self.hi_active(i) {
                    mu_aff +=
                        (self.su[i] - alpha * self.dx[i]) * (self.zu[i] + alpha * self.dzu[i]);
                }
            }
            mu_aff /= m as f64;
            let sigma = (mu_aff / mu).powi(3).clamp(0.0, 1.0);
            // corrector: store affine products in dzl/dzu terms
            for i in 0..n {
                let cl = if self.lo_active(i) { self.dx[i] * self.dzl[i] } else { 0.0 };
                let cu = if self.hi_active(i) { -self.dx[i] * self.dzu[i] } else { 0.0 };
                let mut r = -self.rd[i];
                if self.lo_active(i) {
                    r += (sigma * mu - self.sl[i] * self.zl[i] - cl) / self.sl[i];
                }
                if self.hi_active(i) {
                    r -= (sigma * mu - self.su[i] * self.zu[i] - cu) / self.su[i];
                }
                // keep the affine products for dual_dirs
                self.dzl[i] = cl;
                self.dzu[i] = cu;
                self.rhs[i] = r;
            }
            self.solve_k();
            self.dual_dirs(sigma * mu, Some(()));
            let alpha = (0.99 * self.step_length() / 1.0).min(1.0);
            for i in 0..n {
                self.x[i] += alpha * self.dx[i];
                if self.lo_active(i) {
                    self.sl[i] += alpha * self.dx[i];
                    self.zl[i] += alpha * self.dzl[i];
                }
                if self.hi_active(i) {
                    self.su[i] -= alpha * self.dx[i];
                    self.zu[i] += alpha * self.dzu[i];
                }
            }
        }
        Err(QpFailure::Failed)
    }

    /// Dual directions from `dx`; with `corr`, `dzl/dzu` hold the affine products on entry.
    fn dual_dirs(&mut self, smu: f64, corr: Option<()>) {
        for i in 0..self.n {
            let (cl, cu) = if corr.is_some() { (self.dzl[i], self.dzu[i]) } else { (0.0, 0.0) };
            if self.lo_active(i) {
                self.dzl[i] =
                    (smu - self.sl[i] * self.zl[i] - cl - self.zl[i] * self.dx[i]) / self.sl[i];
            } else {
                self.dzl[i] = 0.0;
            }
            if self.hi_active(i) {
                self.dzu[i] =
                    (smu - self.su[i] * self.zu[i] - cu + self.zu[i] * self.dx[i]) / self.su[i];
            } else {
                self.dzu[i] = 0.0;
            }
        }
    }

    /// Largest step in (0, 1] keeping slacks and duals nonnegative.
    fn step_length(&self) -> f64 {
        let mut a = 1.0_f64;
        for i in 0..self.n {
            if self.lo_active(i) {
                if self.dx[i] < 0.0 {
                    a = a.min(-self.sl[i] / self.dx[i]);
                }
                if self.dzl[i] < 0.0 {
                    a = a.min(-self.zl[i] / self.dzl[i]);
                }
            }
            if self.hi_active(i) {
                if self.dx[i] > 0.0 {
                    a = a.min(self.su[i] / self.dx[i]);
                }
                if self.dzu[i] < 0.0 {
                    a = a.min(-self.zu[i] / self.dzu[i]);
                }
            }
        }
        a
    }
}

/// Clarabel settings used for the QPs.
pub(crate) fn clarabel_settings(tol: f64, max_iter: u32) -> DefaultSettings<f64> {
    DefaultSettings {
        verbose: false,
        max_iter,
        tol_gap_abs: tol,
        tol_gap_rel: tol,
        tol_feas: tol,
        tol_ktratio: 1e-8,
        ..DefaultSettings::default()
    }
}

fn map_status(s: SolverStatus) -> Result<(), QpFailure> {
    match s {
        SolverStatus::Solved | SolverStatus::AlmostSolved => Ok(()),
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
            Err(QpFailure::Infeasible)
        }
        _ => Err(QpFailure::Failed),
    }
}

/// Condensed QP with Clarabel: returns `(Δu, iterations)`, state-bound multipliers in `step.mu`.
pub(crate) fn solve_condensed_clarabel(
    c: &Condenser,
    lin: &Linearisation,
    step: &mut Step,
    du: &mut DVector<f64>,
    tol: f64,
    max_iter: u32,
) -> Result<usize, QpFailure> {
    let nv = c.hc.nrows();
    let (nx, n) = (c.nx, c.n);
    // P: dense upper triangle
    let mut colptr = Vec::with_capacity(nv + 1);
    let mut rowval = Vec::with_capacity(nv * (nv + 1) / 2);
    let mut nzval = Vec::with_capacity(nv * (nv + 1) / 2);
    colptr.push(0);
    for j in 0..nv {
        for i in 0..=j {
            rowval.push(i);
            nzval.push(c.hc[(i, j)]);
        }
        colptr.push(rowval.len());
    }
    let p = CscMatrix::new(nv, nv, colptr, rowval, nzval);
    // rows: Ax ≤ b
    let (mut ti, mut tj, mut tv, mut b) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut row = 0;
    for i in 0..nv {
        if c.hi[i].is_finite() {
            ti.push(row);
            tj.push(i);
            tv.push(1.0);
            b.push(c.hi[i]);
            row += 1;
        }
        if c.lo[i].is_finite() {
            ti.push(row);
            tj.push(i);
            tv.push(-1.0);
            b.push(-c.lo[i]);
            row += 1;
        }
    }
    // state bounds on nodes 1..=N: rows of G
    let mut srows = Vec::new();
    for k in 1..=n {
        for comp in 0..nx {
            let gr = (k - 1) * nx + comp;
            let ncols = k * c.nu;
            for (sign, bound) in [
                (1.0, lin.dx_hi[k][comp] - c.gaff[k][comp]),
                (-1.0, -(lin.dx_lo[k][comp] - c.gaff[k][comp])),
            ] {
                if bound.is_finite() {
                    for j in 0..ncols {
                        let v = c.gmat[(gr, j)];
                        if v != 0.0 {
                            ti.push(row);
                            tj.push(j);
                            tv.push(sign * v);
                        }
                    }
                    b.push(bound);
                    srows.push((k, comp, sign, row));
                    row += 1;
                }
            }
        }
    }
    let a = CscMatrix::new_from_triplets(row, nv, ti, tj, tv);
    let cones = if row > 0 { vec![SupportedConeT::NonnegativeConeT(row)] } else { vec![] };
    let settings = clarabel_settings(tol, max_iter);
    let mut solver = DefaultSolver::new(&p, c.hv.as_slice(), &a, &b, &cones, settings)
        .map_err(|_| QpFailure::Failed)?;
    solver.solve();
    let iters = solver.solution.iterations as usize;
    map_status(solver.solution.status)?;
    du.copy_from_slice(&solver.solution.x);
    for mu in step.mu.iter_mut() {
        mu.fill(0.0);
    }
    for &(k, comp, sign, r) in &srows {
        step.mu[k][comp] += sign * solver.solution.z[r];
    }
    Ok(iters)
}

/// Sparse multiple-shooting QP with Clarabel; writes the whole step.
pub(crate) fn solve_sparse_clarabel(
    lin: &Linearisation,
    step: &mut Step,
    tol: f64,
    max_iter: u32,
) -> Result<usize, QpFailure> {
    let n = lin.a.len();
    let nx = lin.g0.len();
    let nu = lin.r[0].len();
    let st = nx + nu;
    let iu = |k: usize| k * st;
    let is = |k: usize| (k - 1) * st + nu; // k ≥ 1
    let nv = n * st;
    // P upper triangle
    let (mut pi, mut pj, mut pv) = (Vec::new(), Vec::new(), Vec::new());
    let mut q = vec![0.0; nv];
    for k in 0..n {
        for c in 0..nu {
            for r in 0..=c {
                pi.push(iu(k) + r);
                pj.push(iu(k) + c);
                pv.push(lin.hr[k][(r, c)]);
            }
            q[iu(k) + c] = lin.r[k][c];
        }
        if k == 0 {
            // S_0 g_0 enters the gradient of Δu_0
            let mut t = vec![0.0; nu];
            gemv(&mut t, &lin.hs[0], lin.g0.as_slice(), 1.0, false);
            for c in 0..nu {
                q[iu(0) + c] += t[c];
            }
        } else {
            // cross block: rows s_k (earlier index), columns u_k
            for c in 0..nu {
                for r in 0..nx {
                    pi.push(is(k) + r);
                    pj.push(iu(k) + c);
                    pv.push(lin.hs[k][(c, r)]);
                }
            }
        }
    }
    for k in 1..=n {
        for c in 0..nx {
            for r in 0..=c {
                pi.push(is(k) + r);
                pj.push(is(k) + c);
                pv.push(lin.hq[k][(r, c)]);
            }
            q[is(k) + c] = lin.q[k][c];
        }
    }
    let p = CscMatrix::new_from_triplets(nv, nv, pi, pj, pv);
    // equality rows: A_kΔs_k + B_kΔu_k − Δs_{k+1} = −d_k (− A_0 g_0 for k = 0)
    let (mut ai, mut aj, mut av, mut b) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut t = vec![0.0; nx];
    for k in 0..n {
        let r0 = k * nx;
        for r in 0..nx {
            if k > 0 {
                for c in 0..nx {
                    ai.push(r0 + r);
                    aj.push(is(k) + c);
                    av.push(lin.a[k][(r, c)]);
                }
            }
            for c in 0..nu {
                ai.push(r0 + r);
                aj.push(iu(k) + c);
                av.push(lin.b[k][(r, c)]);
            }
            ai.push(r0 + r);
            aj.push(is(k + 1) + r);
            av.push(-1.0);
        }
        if k == 0 {
            gemv(&mut t, &lin.a[0], lin.g0.as_slice(), 1.0, false);
        }
        for r in 0..nx {
            b.push(-lin.d[k][r] - if k == 0 { t[r] } else { 0.0 });
        }
    }
    let neq = n * nx;
    let mut row = neq;
    let mut srows = Vec::new();
    for k in 0..n {
        for c in 0..nu {
            for (sign, bound) in [(1.0, lin.du_hi[k][c]), (-1.0, -lin.du_lo[k][c])] {
                if bound.is_finite() {
                    ai.push(row);
                    aj.push(iu(k) + c);
                    av.push(sign);
                    b.push(bound);
                    row += 1;
                }
            }
        }
    }
    for k in 1..=n {
        for c in 0..nx {
            for (sign, bound) in [(1.0, lin.dx_hi[k][c]), (-1.0, -lin.dx_lo[k][c])] {
                if bound.is_finite() {
                    ai.push(row);
                    aj.push(is(k) + c);
                    av.push(sign);
                    b.push(bound);
                    srows.push((k, c, sign, row));
                    row += 1;
                }
            }
        }
    }
    let a = CscMatrix::new_from_triplets(row, nv, ai, aj, av);
    let mut cones = vec![SupportedConeT::ZeroConeT(neq)];
    if row > neq {
        cones.push(SupportedConeT::NonnegativeConeT(row - neq));
    }
    let settings = clarabel_settings(tol, max_iter);
    let mut solver =
        DefaultSolver::new(&p, &q, &a, &b, &cones, settings).map_err(|_| QpFailure::Failed)?;
    solver.solve();
    let iters = solver.solution.iterations as usize;
    map_status(solver.solution.status)?;
    let x = &solver.solution.x;
    let z = &solver.solution.z;
    step.ds[0].copy_from(&lin.g0);
    for k in 0..n {
        step.du[k].copy_from_slice(&x[iu(k)..iu(k) + nu]);
        step.ds[k + 1].copy_from_slice(&x[is(k + 1)..is(k + 1) + nx]);
    }
    for mu in step.mu.iter_mut() {
        mu.fill(0.0);
    }
    for &(k, c, sign, r) in &srows {
        step.mu[k][c] += sign * z[r];
    }
    // multipliers by the same backward recursion as the condensed form (consistent with z)
    multipliers(lin, step);
    Ok(iters)
}
