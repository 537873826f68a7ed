//! One-interval integrators with exact forward sensitivities: RK4, implicit midpoint and
//! Lawson (exponential) RK4.
//!
//! Each integrates `ẋ = f(x, u)` over one shooting interval of length `Δt` with `n` equal
//! substeps `h = Δt/n` and `u` constant, and returns `x⁺ = Φ(x, u)`, optionally with the
//! exact derivatives of the *discrete* map, `A = ∂Φ/∂x` and `B = ∂Φ/∂u`, propagated
//! alongside the state (internal numerical differentiation: each stage's Jacobian is
//! evaluated once and reused by the state and all `nx + nu` sensitivity directions).
//!
//! * **RK4**: the classical method.
//! * **Implicit midpoint** (Gauss–Legendre, one stage): `m = x + h/2 f(m, u)`,
//!   `x⁺ = 2m − x`, solved by simplified Newton: the first step of a substep uses the
//!   interval's last factorised Newton matrix `I − h/2 ∂f/∂x` (the previous substep's, or a
//!   recorded one near a linearisation: [`Integrator::integrate_near`]), the iterate after it
//!   evaluates the Jacobian with its residual and refactorises
//!   ([`IntegratorSettings::refresh_after_first_step`]; without it, one Jacobian per interval
//!   when the iteration contracts), and later ones re-evaluate it only when the residual
//!   contracts slower than [`SIMPLIFIED_NEWTON_MAX_RATE`] (full Newton with
//!   [`IntegratorSettings::simplified_newton`] off); the
//!   sensitivities follow from the implicit function theorem with the Newton matrix
//!   re-factorised at the converged point (exact, whichever iteration found it).
//!   Symplectic and quadratic-invariant preserving (keeps `½xᵀx` when `xᵀf(x) = 0`).
//! * **Lawson RK4**: RK4 applied to `v = e^{−tL}x`, with `L` a constant matrix (the
//!   stiff linear part): with `E = e^{hL/2}` and `g(x) = f(x, u) − Lx`,
//!   `k1 = g(x)`, `k2 = g(E(x + h/2 k1))`, `k3 = g(Ex + h/2 k2)`, `k4 = g(E²x + hEk3)`,
//!   `x⁺ = E²x + h/6 (E²k1 + 2E(k2 + k3) + k4)`. Exact for `ẋ = Lx`; `E` is computed once
//!   (nalgebra's Padé scaling-and-squaring `exp`) and applied sparsely when it is sparse
//!   (block-diagonal modal `W`). `Ex` and `Ek1` (and their sensitivities) are shared by the
//!   later stages (`X4 = E(Ex + hk3)`, `x⁺ = E(Ex + h/6 Ek1 + h/3(k2 + k3)) + h/6 k4`): four
//!   propagator products per substep.
//!
//! For the explicit methods, [`Integrator::adjoint_hessian`] also returns the exact second
//! derivative `∇²_{(x,u)} (λᵀΦ)`: the only nonlinear operations are evaluations of `f`, so
//! `∇²(λᵀΦ) = Σ_stages Ŝⱼᵀ (Σ_i k̄ⱼ,ᵢ ∇²fᵢ(Xⱼ, u)) Ŝⱼ` with `Ŝⱼ = ∂(Xⱼ, u)/∂(x, u)` the forward
//! sensitivities of the stage inputs (taped) and `k̄ⱼ` the adjoints of the stage slopes
//! (one backward sweep).

mod adjoint;
mod settings;
mod stages;
mod warm_start;

pub use settings::{
    interval_error, AdaptiveSubsteps, IntegratorKind, IntegratorSettings, LinearPart, TailSubsteps,
    SIMPLIFIED_NEWTON_MAX_RATE,
};
pub use warm_start::MidpointRecord;
use warm_start::Warm;

use crate::dynamics::Dynamics;
use crate::error::{check_dim, invalid, OcpError, Result};
use crate::la::{all_finite, axpy, norm_inf, Operator};
use faer::dyn_stack::{MemBuffer, StackReq};
use faer::linalg::lu::partial_pivoting::{factor as lu_factor, solve as lu_solve};
use faer::Par;
use nalgebra::DMatrix;

#[derive(Clone, Debug)]
struct Lawson {
    l: DMatrix<f64>,
    l_op: Operator,
    /// `(E, E²)` with `E = e^{hL/2}`, `h = Δt/n`, for the counts `n = first, first + 1, …`.
    props: Vec<(Operator, Operator)>,
    first: usize,
    /// Index of the current count in `props`.
    cur: usize,
}

/// Which power of `E` to apply (identity for plain RK4).
#[derive(Clone, Copy)]
enum Pow {
    E1,
    E2,
}

impl Lawson {
    /// The operator of `E^p`.
    fn power(&self, p: Pow) -> &Operator {
        let (e, e2) = &self.props[self.cur];
        match p {
            Pow::E1 => e,
            Pow::E2 => e2,
        }
    }
}

/// An integrator over one shooting interval with its workspace (allocated at construction;
/// integrating does not allocate).
pub struct Integrator {
    kind: IntegratorKind,
    nx: usize,
    nu: usize,
    substeps: usize,
    /// Counts this integrator can run (`set_substeps`).
    range: (usize, usize),
    adaptive: Option<AdaptiveSubsteps>,
    interval: f64,
    h: f64,
    lawson: Option<Lawson>,
    /// Lawson with `L` = the model's linear part: [`Dynamics::remainder_and_jacobians`] applies.
    model_linear_part: bool,
    newton_tolerance: f64,
    newton_max_iterations: usize,
    simplified_newton: bool,
    refresh_after_first_step: bool,
    /// `lu` holds a factorised Newton matrix for the current `h`, evaluated in this interval
    /// integration (reset at the start of each, so that an integration is a function of its
    /// arguments alone: same bits whichever interval the workspace integrated before).
    newton_factored: bool,
    /// The previous Newton iterate and its residual (to undo a simplified step that diverged).
    m_prev: Vec<f64>,
    r_prev: Vec<f64>,
    x: Vec<f64>,
    xs: Vec<f64>,
    t: Vec<f64>,
    ex: Vec<f64>,
    ek1: Vec<f64>,
    es: DMatrix<f64>,
    eks: DMatrix<f64>,
    k: [Vec<f64>; 4],
    fx: DMatrix<f64>,
    fu: DMatrix<f64>,
    s: DMatrix<f64>,
    sx: DMatrix<f64>,
    tm: DMatrix<f64>,
    ks: [DMatrix<f64>; 4],
    tcm: DMatrix<f64>,
    rows: crate::la::SparseRows,
    lu: DMatrix<f64>,
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    mem: MemBuffer,
    tape_x: Vec<Vec<f64>>,
    tape_s: Vec<DMatrix<f64>>,
    kbar: [Vec<f64>; 4],
    xbar: [Vec<f64>; 4],
    lbar: Vec<f64>,
    whess: DMatrix<f64>,
    shat: DMatrix<f64>,
    zz: DMatrix<f64>,
    calls: usize,
    evaluations: Evaluations,
}

/// Work done by an integrator (or a solver's integrators) so far, counted per model call: a
/// machine-independent measure of cost next to the clocks (the same inputs give the same
/// counts, whatever the machine or its load).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Evaluations {
    /// Right-hand sides `f(x, u)` (or the remainder `f − Lx`) evaluated alone.
    pub rhs: usize,
    /// Jacobians `∂f/∂x`, `∂f/∂u` (with or without the right-hand side at the same point).
    pub jacobians: usize,
    /// Weighted second derivatives `∇²(wᵀf)` (exact Hessians of explicit methods).
    pub hessians: usize,
    /// LU factorisations of an implicit midpoint Newton matrix `I − h/2 ∂f/∂x`.
    pub factorisations: usize,
}

impl std::ops::Add for Evaluations {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            rhs: self.rhs + o.rhs,
            jacobians: self.jacobians + o.jacobians,
            hessians: self.hessians + o.hessians,
            factorisations: self.factorisations + o.factorisations,
        }
    }
}

impl std::ops::Sub for Evaluations {
    type Output = Self;
    /// The work between two readings (`later − earlier`, saturating at zero).
    fn sub(self, o: Self) -> Self {
        Self {
            rhs: self.rhs.saturating_sub(o.rhs),
            jacobians: self.jacobians.saturating_sub(o.jacobians),
            hessians: self.hessians.saturating_sub(o.hessians),
            factorisations: self.factorisations.saturating_sub(o.factorisations),
        }
    }
}

impl std::iter::Sum for Evaluations {
    fn sum<I: Iterator<Item = Self>>(iter: I) -> Self {
        iter.fold(Self::default(), |a, b| a + b)
    }
}

impl std::fmt::Debug for Integrator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Integrator")
            .field("kind", &self.kind)
            .field("nx", &self.nx)
            .field("nu", &self.nu)
            .field("substeps", &self.substeps)
            .field("interval", &self.interval)
            .finish()
    }
}

impl Integrator {
    /// Builds the integrator for `model` over an interval of length `interval` (> 0).
    pub fn new<D: Dynamics + ?Sized>(
        model: &D,
        settings: &IntegratorSettings,
        interval: f64,
    ) -> Result<Self> {
        settings.validate()?;
        if !(interval > 0.0 && interval.is_finite()) {
            return Err(invalid("interval", interval, "must be positive and finite"));
        }
        let nx = model.nx();
        let nu = model.nu();
        if nx == 0 {
            return Err(invalid("nx", nx, "the model must have at least one state"));
        }
        let h = interval / settings.substeps as f64;
        let lawson = if settings.kind == IntegratorKind::LawsonRk4 {
            let l = match &settings.linear_part {
                LinearPart::Model => model.linear_part().ok_or(OcpError::Unsupported {
                    what: "LinearPart::Model with a model whose linear_part() is None",
                })?,
                LinearPart::Matrix(m) => m.clone(),
            };
            check_dim("linear part rows", nx, l.nrows())?;
            check_dim("linear part columns", nx, l.ncols())?;
            if !all_finite(l.as_slice()) {
                return Err(OcpError::NonFiniteDynamics { stage: "linear part" });
            }
            let (first, last) = settings.count_range();
            let mut props = Vec::with_capacity(last - first + 1);
            for n in first..=last {
                let e = (&l * (0.5 * interval / n as f64)).exp();
                let e2 = &e * &e;
                if !all_finite(e2.as_slice()) {
                    return Err(OcpError::NonFiniteDynamics { stage: "matrix exponential" });
                }
                props.push((Operator::new(e), Operator::new(e2)));
            }
            Some(Lawson {
                l_op: Operator::new(l.clone()),
                l,
                props,
                first,
                cur: settings.substeps - first,
            })
        } else {
            None
        };
        let nz = nx + nu;
        let req = StackReq::any_of(&[
            lu_factor::lu_in_place_scratch::<usize, f64>(nx, nx, Par::Seq, Default::default()),
            lu_solve::solve_in_place_scratch::<usize, f64>(nx, nz, Par::Seq),
        ]);
        let zv = || vec![0.0; nx];
        // sensitivities are stored transposed, `Sᵀ` (`(nx+nu) × nx`): row i of `S` is a
        // contiguous column, so sparse Jacobians and block-diagonal propagators act by axpys
        let zm = || DMatrix::zeros(nz, nx);
        Ok(Self {
            kind: settings.kind,
            nx,
            nu,
            substeps: settings.substeps,
            range: settings.count_range(),
            adaptive: settings.adaptive.clone(),
            interval,
            h,
            model_linear_part: lawson.is_some() && settings.linear_part == LinearPart::Model,
            lawson,
            newton_tolerance: settings.newton_tolerance,
            newton_max_iterations: settings.newton_max_iterations,
            simplified_newton: settings.simplified_newton,
            refresh_after_first_step: settings.refresh_after_first_step,
            newton_factored: false,
            m_prev: zv(),
            r_prev: zv(),
            x: zv(),
            xs: zv(),
            t: zv(),
            ex: zv(),
            ek1: zv(),
            es: zm(),
            eks: zm(),
            k: [zv(), zv(), zv(), zv()],
            fx: DMatrix::zeros(nx, nx),
            fu: DMatrix::zeros(nx, nu),
            s: zm(),
            sx: zm(),
            tm: zm(),
            ks: [zm(), zm(), zm(), zm()],
            rows: crate::la::SparseRows::with_capacity(nx),
            tcm: if settings.kind == IntegratorKind::ImplicitMidpoint {
                DMatrix::zeros(nx, nz)
            } else {
                DMatrix::zeros(0, 0)
            },
            lu: if settings.kind == IntegratorKind::ImplicitMidpoint {
                DMatrix::zeros(nx, nx)
            } else {
                DMatrix::zeros(0, 0)
            },
            perm: vec![0; nx],
            perm_inv: vec![0; nx],
            mem: MemBuffer::new(req),
            tape_x: Vec::new(),
            tape_s: Vec::new(),
            kbar: [zv(), zv(), zv(), zv()],
            xbar: [zv(), zv(), zv(), zv()],
            lbar: zv(),
            whess: DMatrix::zeros(0, 0),
            shat: DMatrix::zeros(0, 0),
            zz: DMatrix::zeros(0, 0),
            calls: 0,
            evaluations: Evaluations::default(),
        })
    }

    /// The method.
    pub fn kind(&self) -> IntegratorKind {
        self.kind
    }
    /// Substeps per interval (the current count).
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    /// The counts [`Integrator::set_substeps`] accepts: `(min, max)` of the adaptive table,
    /// or the fixed count twice.
    pub fn substep_range(&self) -> (usize, usize) {
        self.range
    }

    /// The adaptive table, if any.
    pub fn adaptive(&self) -> Option<&AdaptiveSubsteps> {
        self.adaptive.as_ref()
    }

    /// Switches to `n` substeps (within [`Integrator::substep_range`]; the Lawson propagators
    /// of every count in the range are computed at construction, so this does not allocate).
    pub fn set_substeps(&mut self, n: usize) -> Result<()> {
        if n < self.range.0 || n > self.range.1 {
            return Err(invalid(
                "substeps",
                n,
                "must lie in the integrator's substep range (adaptive.min/max_substeps)",
            ));
        }
        self.substeps = n;
        self.h = self.interval / n as f64;
        if let Some(lw) = &mut self.lawson {
            lw.cur = n - lw.first;
        }
        Ok(())
    }

    /// The error indicators of [`AdaptiveSubsteps`] at `(x, u)`: `ρ_x = ‖∂f/∂x − L‖∞` and
    /// `ρ_l = ‖Lx‖∞` (maximised over `x` and `x_next` when given), `ρ_u = ‖∂f/∂u u‖∞`. Uses the Jacobian
    /// workspace; no allocation. Dimensions are the caller's responsibility (as for
    /// [`Dynamics`]).
    pub fn indicators<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x: &[f64],
        u: &[f64],
        x_next: Option<&[f64]>,
    ) -> (f64, f64, f64) {
        let mut rho_x = 0.0_f64;
        let mut rho_u = 0.0_f64;
        let mut rho_l = 0.0_f64;
        for (p, point) in std::iter::once(x).chain(x_next).enumerate() {
            self.evaluations.jacobians += 1;
            model.jacobians(point, u, &mut self.fx, &mut self.fu);
            if let Some(lw) = &self.lawson {
                self.fx -= &lw.l;
                lw.l_op.apply_vec(&mut self.t, point, 1.0, false);
                rho_l = rho_l.max(norm_inf(&self.t));
            }
            for i in 0..self.nx {
                let mut r = 0.0;
                for j in 0..self.nx {
                    r += self.fx[(i, j)].abs();
                }
                rho_x = if r.is_nan() { f64::NAN } else { rho_x.max(r) };
            }
            if p == 0 {
                for i in 0..self.nx {
                    let mut f = 0.0;
                    for c in 0..self.nu {
                        f += self.fu[(i, c)] * u[c];
                    }
                    rho_u = if f.is_nan() { f64::NAN } else { rho_u.max(f.abs()) };
                }
            }
        }
        (rho_x, rho_u, rho_l)
    }

    /// The count the adaptive table chooses for an interval from `x` with control `u`
    /// (and end node `x_next` when known); the current count when not adaptive.
    pub fn choose_substeps<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x: &[f64],
        u: &[f64],
        x_next: Option<&[f64]>,
    ) -> usize {
        let Some(a) = self.adaptive.clone() else {
            return self.substeps;
        };
        let rho = self.indicators(model, x, u, x_next);
        a.substeps_for(self.interval, rho)
    }
    /// Interval length `Δt`.
    pub fn interval(&self) -> f64 {
        self.interval
    }
    /// Number of interval integrations performed so far.
    pub fn calls(&self) -> usize {
        self.calls
    }
    /// Model evaluations and factorisations performed so far ([`Evaluations`]).
    pub fn evaluations(&self) -> Evaluations {
        self.evaluations
    }

    /// Allocates the tape used by [`Integrator::adjoint_hessian`] (explicit methods only).
    pub fn enable_second_order(&mut self) -> Result<()> {
        if self.kind == IntegratorKind::ImplicitMidpoint {
            return Err(OcpError::Unsupported {
                what: "exact Hessian with the implicit midpoint integrator",
            });
        }
        let n = 4 * self.range.1;
        let nz = self.nx + self.nu;
        if self.tape_x.len() != n {
            self.tape_x = vec![vec![0.0; self.nx]; n];
            self.tape_s = vec![DMatrix::zeros(nz, self.nx); n];
            self.whess = DMatrix::zeros(nz, nz);
            self.shat = DMatrix::zeros(nz, nz);
            self.zz = DMatrix::zeros(nz, nz);
        }
        Ok(())
    }

    fn check_args(&self, x0: &[f64], u: &[f64], x_end: &[f64]) -> Result<()> {
        check_dim("x0", self.nx, x0.len())?;
        check_dim("u", self.nu, u.len())?;
        check_dim("x_end", self.nx, x_end.len())
    }

    /// `x_end = Φ(x0, u)`.
    pub fn integrate<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        x_end: &mut [f64],
    ) -> Result<()> {
        self.check_args(x0, u, x_end)?;
        self.run(model, x0, u, false, false)?;
        x_end.copy_from_slice(&self.x);
        Ok(())
    }

    /// `x_end = Φ(x0, u)`, `a = ∂Φ/∂x0` (`nx × nx`), `b = ∂Φ/∂u` (`nx × nu`).
    pub fn integrate_with_sensitivities<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        x_end: &mut [f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) -> Result<()> {
        self.check_args(x0, u, x_end)?;
        self.sensitivities_warm(model, x0, u, x_end, a, b, Warm::Cold)
    }

    /// The shared body of the sensitivity integrations (arguments `x0`, `u`, `x_end` checked by
    /// the caller): checks `a`, `b`, integrates with `warm`, writes `x_end`, `a`, `b`.
    #[allow(clippy::too_many_arguments)]
    fn sensitivities_warm<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        x_end: &mut [f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
        warm: Warm<'_>,
    ) -> Result<()> {
        check_dim("a rows", self.nx, a.nrows())?;
        check_dim("a columns", self.nx, a.ncols())?;
        check_dim("b rows", self.nx, b.nrows())?;
        check_dim("b columns", self.nu, b.ncols())?;
        self.run_warm(model, x0, u, true, false, warm)?;
        x_end.copy_from_slice(&self.x);
        self.write_ab(a, b);
        Ok(())
    }

    /// Exact `out = ∇²_{(x0,u)} (λᵀ Φ(x0, u))`, a symmetric `(nx+nu)²` matrix (explicit methods;
    /// call [`Integrator::enable_second_order`] first). Needs [`Dynamics::weighted_hessian`].
    pub fn adjoint_hessian<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        lambda: &[f64],
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        check_dim("x0", self.nx, x0.len())?;
        check_dim("u", self.nu, u.len())?;
        check_dim("lambda", self.nx, lambda.len())?;
        let nz = self.nx + self.nu;
        check_dim("hessian rows", nz, out.nrows())?;
        check_dim("hessian columns", nz, out.ncols())?;
        if self.tape_x.len() < 4 * self.substeps {
            return Err(OcpError::Unsupported {
                what: "adjoint_hessian before enable_second_order",
            });
        }
        self.run(model, x0, u, true, true)?;
        self.backward(model, u, lambda, out)
    }

    /// [`Integrator::integrate_with_sensitivities`] and [`Integrator::adjoint_hessian`] in one
    /// forward pass (the taped pass also yields `A` and `B`).
    pub fn integrate_with_hessian<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        lambda: &[f64],
        x_end: &mut [f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
        hessian: &mut DMatrix<f64>,
    ) -> Result<()> {
        self.check_args(x0, u, x_end)?;
        check_dim("lambda", self.nx, lambda.len())?;
        let nz = self.nx + self.nu;
        check_dim("a", self.nx * self.nx, a.len())?;
        check_dim("b", self.nx * self.nu, b.len())?;
        check_dim("hessian", nz * nz, hessian.len())?;
        if self.tape_x.len() < 4 * self.substeps {
            return Err(OcpError::Unsupported {
                what: "integrate_with_hessian before enable_second_order",
            });
        }
        self.run(model, x0, u, true, true)?;
        x_end.copy_from_slice(&self.x);
        self.write_ab(a, b);
        self.backward(model, u, lambda, hessian)
    }

    fn run<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        sens: bool,
        tape: bool,
    ) -> Result<()> {
        self.run_warm(model, x0, u, sens, tape, Warm::Cold)
    }

    /// One interval integration; `warm` records the implicit midpoint substeps or starts
    /// their Newton iterations from a record (`warm_start`).
    fn run_warm<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        sens: bool,
        tape: bool,
        mut warm: Warm<'_>,
    ) -> Result<()> {
        self.calls += 1;
        self.newton_factored = false;
        self.x.copy_from_slice(x0);
        if sens {
            self.s.fill(0.0);
            for i in 0..self.nx {
                self.s[(i, i)] = 1.0;
            }
        }
        for n in 0..self.substeps {
            match self.kind {
                IntegratorKind::ImplicitMidpoint => {
                    self.midpoint_substep(model, u, sens, n, &mut warm)?
                }
                _ => {
                    self.explicit_substep(model, u, sens, if tape { Some(4 * n) } else { None })?
                }
            }
            if !all_finite(&self.x) {
                return Err(OcpError::NonFiniteDynamics { stage: "state" });
            }
        }
        if sens && !all_finite(self.s.as_slice()) {
            return Err(OcpError::NonFiniteDynamics { stage: "sensitivity" });
        }
        match warm {
            Warm::Record { record, .. } => self.finish_record(record, u),
            Warm::Start(record) => self.finish_path(record, x0, u),
            Warm::Cold => {}
        }
        Ok(())
    }

    /// `A = S[:, ..nx]`, `B = S[:, nx..]` from the transposed storage.
    fn write_ab(&self, a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        let nx = self.nx;
        for i in 0..nx {
            for j in 0..nx {
                a[(i, j)] = self.s[(j, i)];
            }
            for c in 0..self.nu {
                b[(i, c)] = self.s[(nx + c, i)];
            }
        }
    }

    /// `dst = alpha * E^p * src` (+= when add); identity for plain RK4.
    fn pow_vec(
        lawson: &Option<Lawson>,
        p: Pow,
        dst: &mut [f64],
        src: &[f64],
        alpha: f64,
        add: bool,
    ) {
        match lawson {
            Some(lw) => lw.power(p).apply_vec(dst, src, alpha, add),
            None => {
                if add {
                    axpy(dst, alpha, src)
                } else {
                    for (d, s) in dst.iter_mut().zip(src) {
                        *d = alpha * s;
                    }
                }
            }
        }
    }

    fn pow_mat(
        lawson: &Option<Lawson>,
        p: Pow,
        dst: &mut DMatrix<f64>,
        src: &DMatrix<f64>,
        alpha: f64,
        add: bool,
    ) {
        match lawson {
            Some(lw) => lw.power(p).apply_right_t(dst, src, alpha, add),
            None => {
                if add {
                    axpy(dst.as_mut_slice(), alpha, src.as_slice())
                } else {
                    dst.copy_from(src);
                    if alpha != 1.0 {
                        *dst *= alpha;
                    }
                }
            }
        }
    }

    /// Transposed power on a vector.
    fn pow_t_vec(
        lawson: &Option<Lawson>,
        p: Pow,
        dst: &mut [f64],
        src: &[f64],
        alpha: f64,
        add: bool,
    ) {
        match lawson {
            Some(lw) => lw.power(p).apply_t_vec(dst, src, alpha, add),
            None => Self::pow_vec(&None, p, dst, src, alpha, add),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::ModalLike;

    /// The exponential of the block-diagonal modal `W` keeps its block structure, so the
    /// Lawson propagators are applied sparsely.
    #[test]
    fn lawson_propagator_of_block_diagonal_w_is_sparse() {
        let m = ModalLike::new(61, 5, 175.0, 3.0, 7).unwrap();
        let int = Integrator::new(&m, &IntegratorSettings::new(IntegratorKind::LawsonRk4, 8), 0.25)
            .unwrap();
        let lw = int.lawson.as_ref().unwrap();
        for op in [&lw.props[0].0, &lw.props[0].1] {
            let nnz = op.dense().iter().filter(|v| **v != 0.0).count();
            assert!(matches!(op, Operator::BlockDiagonal { .. }), "nnz {nnz}");
            assert!(nnz <= 4 * 30 + 1, "nnz {nnz}");
        }
    }
}
