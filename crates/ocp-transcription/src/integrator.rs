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
//!   `x⁺ = 2m − x`, solved by Newton; the sensitivities follow from the implicit function
//!   theorem with the Newton matrix `I − h/2 ∂f/∂x` re-factorised at the converged point.
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

use crate::dynamics::Dynamics;
use crate::error::{check_dim, invalid, OcpError, Result};
use crate::la::{all_finite, axpy, gemm, gemv_t, lincomb, norm_inf, Operator};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::lu::partial_pivoting::{factor as lu_factor, solve as lu_solve};
use faer::{Conj, Par};
use nalgebra::DMatrix;

/// Which one-step method runs inside a shooting interval.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum IntegratorKind {
    /// Classical explicit Runge–Kutta of order 4.
    Rk4,
    /// Implicit midpoint rule (one-stage Gauss–Legendre, order 2), Newton inside.
    ImplicitMidpoint,
    /// Lawson exponential RK4 (order 4, exact on the linear part `L`).
    LawsonRk4,
}

/// The constant linear part `L` of the Lawson integrator.
#[derive(Clone, Debug, PartialEq)]
pub enum LinearPart {
    /// Take `L` from [`Dynamics::linear_part`] (error if the model has none).
    Model,
    /// A given `nx × nx` matrix, e.g. the Jacobian of `f` at a reference state.
    Matrix(DMatrix<f64>),
}

/// Settings of the shooting-interval integrator.
#[derive(Clone, Debug, PartialEq)]
pub struct IntegratorSettings {
    /// Method. Default [`IntegratorKind::Rk4`].
    pub kind: IntegratorKind,
    /// Substeps per shooting interval, `≥ 1`. Default 4.
    pub substeps: usize,
    /// Linear part for [`IntegratorKind::LawsonRk4`]. Default [`LinearPart::Model`].
    pub linear_part: LinearPart,
    /// Newton tolerance of the implicit midpoint rule on `‖r‖∞ / (1 + ‖m‖∞)`, in (0, 1e-2].
    /// Default 1e-13 (sensitivities are exact up to this residual).
    pub newton_tolerance: f64,
    /// Newton iteration limit, `≥ 1`. Default 30.
    pub newton_max_iterations: usize,
    /// State-adapted substep counts (explicit methods): each shooting interval's count is
    /// chosen from its nodes and control by an error table, fixed during one SQP iteration.
    /// `None` (default): every interval uses `substeps`.
    pub adaptive: Option<AdaptiveSubsteps>,
}

/// An a priori one-interval error table for choosing substep counts from the state.
///
/// Model (explicit methods of order 4):
/// `err(n) ≈ (Δt/n)⁴ (c_x ρ_x² + c_u ρ_u + c_l ρ_l²)` with `ρ_x = ‖∂f/∂x(x, u) − L‖∞` (the
/// part of the Jacobian the method does not integrate exactly; `L = 0` for RK4), `ρ_u =
/// ‖∂f/∂u(x, u) u‖∞` (the forcing, which excites the fast modes of `L`) and `ρ_l = ‖Lx‖∞`
/// (motion in the fast modes), `ρ_x` and `ρ_l` at the interval's start node, maximised
/// with the end node when it is known. On the ROM-structured sample each part was measured
/// to grow like its term and like `n⁻⁴` (docs/ocp-transcription.md); the constants are
/// fitted per model by [`AdaptiveSubsteps::calibrate`]. The count is the smallest
/// `n ∈ [min_substeps, max_substeps]` with `err(n) ≤ tolerance`.
#[derive(Clone, Debug, PartialEq)]
pub struct AdaptiveSubsteps {
    /// Target one-interval error (the error measure of the calibration: max norm relative to
    /// `max(‖x⁺‖∞, 1)`), in (0, 1). Default 1e-3.
    pub tolerance: f64,
    /// `c_x ≥ 0`. Default 15 (the Lawson RK4 fit on `ModalLike::paper_sized_rom`).
    pub state_constant: f64,
    /// `c_u ≥ 0`. Default 5000 (same fit).
    pub input_constant: f64,
    /// `c_l ≥ 0`. Default 64 (same fit).
    pub fast_constant: f64,
    /// Smallest count, `≥ 1`. Default 8 (below it the error leaves the `n⁻⁴` regime when
    /// `Δt ω_max` is large).
    pub min_substeps: usize,
    /// Largest count, `≥ min_substeps`, at most 1024 (one propagator per count is precomputed).
    /// Default 48.
    pub max_substeps: usize,
}

impl Default for AdaptiveSubsteps {
    fn default() -> Self {
        Self {
            tolerance: 1e-3,
            state_constant: 15.0,
            input_constant: 5000.0,
            fast_constant: 64.0,
            min_substeps: 8,
            max_substeps: 48,
        }
    }
}

/// The one-interval error measure of the calibration: `‖x − x_ref‖∞ / max(‖x_ref‖∞, 1)`.
pub fn interval_error(x: &[f64], x_ref: &[f64]) -> f64 {
    let d = x.iter().zip(x_ref).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    d / norm_inf(x_ref).max(1.0)
}

impl AdaptiveSubsteps {
    /// Checks the ranges documented on each field.
    pub fn validate(&self) -> Result<()> {
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(invalid("adaptive.tolerance", self.tolerance, "must be in (0, 1)"));
        }
        for (name, v) in [
            ("adaptive.state_constant", self.state_constant),
            ("adaptive.input_constant", self.input_constant),
            ("adaptive.fast_constant", self.fast_constant),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(invalid(name, v, "must be finite and ≥ 0"));
            }
        }
        if self.min_substeps == 0 {
            return Err(invalid("adaptive.min_substeps", self.min_substeps, "must be at least 1"));
        }
        if self.max_substeps < self.min_substeps || self.max_substeps > 1024 {
            return Err(invalid(
                "adaptive.max_substeps",
                self.max_substeps,
                "must be in [min_substeps, 1024]",
            ));
        }
        Ok(())
    }

    /// Predicted one-interval error with `n` substeps over `interval` for the indicators
    /// `rho = (ρ_x, ρ_u, ρ_l)`.
    pub fn predicted_error(&self, interval: f64, n: usize, rho: (f64, f64, f64)) -> f64 {
        let (x, u, l) = rho;
        (interval / n as f64).powi(4)
            * (self.state_constant * x * x + self.input_constant * u + self.fast_constant * l * l)
    }

    /// The smallest count in `[min_substeps, max_substeps]` whose predicted error meets the
    /// tolerance (`max_substeps` when none does, or when an indicator is not finite).
    pub fn substeps_for(&self, interval: f64, rho: (f64, f64, f64)) -> usize {
        if !(rho.0.is_finite() && rho.1.is_finite() && rho.2.is_finite()) {
            return self.max_substeps;
        }
        // err(n) = C n⁻⁴ ≤ tol  ⇔  n ≥ (C / tol)^{1/4}
        let c = self.predicted_error(interval, 1, rho);
        let n = (c / self.tolerance).powf(0.25).ceil();
        if n.is_nan() || n > self.max_substeps as f64 {
            return self.max_substeps;
        }
        let mut n = (n as usize).max(self.min_substeps);
        // guard the rounding of the fourth root
        while n < self.max_substeps && self.predicted_error(interval, n, rho) > self.tolerance {
            n += 1;
        }
        n
    }

    /// Fits the three constants for `model` and the method of `settings` (its `adaptive`
    /// field is ignored) from sample points `(x, u)`: the one-interval errors against a
    /// reference with `reference_substeps` substeps are measured at the counts
    /// `probe_substeps`, and among the ratios `c_u / c_x`, `c_l / c_x` on logarithmic grids
    /// (10⁻³ … 10⁶) the tightest model that over-predicts *every* measured error is kept
    /// (smallest total log over-prediction). Errors below 1e-12 are ignored (round-off).
    /// `tolerance`, `min_substeps`, `max_substeps` are copied into the result.
    #[allow(clippy::too_many_arguments)]
    pub fn calibrate<D: Dynamics + ?Sized>(
        model: &D,
        settings: &IntegratorSettings,
        interval: f64,
        samples: &[(Vec<f64>, Vec<f64>)],
        probe_substeps: &[usize],
        reference_substeps: usize,
        tolerance: f64,
        min_substeps: usize,
        max_substeps: usize,
    ) -> Result<Self> {
        if samples.is_empty() {
            return Err(invalid("samples", 0, "need at least one calibration sample"));
        }
        if probe_substeps.is_empty() {
            return Err(invalid("probe_substeps", 0, "need at least one probe count"));
        }
        let base = IntegratorSettings { adaptive: None, ..settings.clone() };
        let mut reference = Integrator::new(
            model,
            &IntegratorSettings { substeps: reference_substeps, ..base.clone() },
            interval,
        )?;
        let mut probes = probe_substeps
            .iter()
            .map(|&n| {
                Integrator::new(
                    model,
                    &IntegratorSettings { substeps: n, ..base.clone() },
                    interval,
                )
            })
            .collect::<Result<Vec<_>>>()?;
        // (h⁴-scaled) measurements: err / (Δt/n)⁴ = c_x a + c_u b + c_l c
        let mut data: Vec<(f64, f64, f64, f64)> = Vec::new();
        let nx = model.nx();
        let (mut xr, mut xe) = (vec![0.0; nx], vec![0.0; nx]);
        for (x, u) in samples {
            reference.integrate(model, x, u, &mut xr)?;
            let (a, b, c) = reference.indicators(model, x, u, Some(&xr));
            for (int, &n) in probes.iter_mut().zip(probe_substeps) {
                int.integrate(model, x, u, &mut xe)?;
                let e = interval_error(&xe, &xr);
                if e > 1e-12 {
                    data.push((e / (interval / n as f64).powi(4), a * a, b, c * c));
                }
            }
        }
        let mut best: Option<(f64, f64, f64, f64)> = None;
        let grid = |k: i32| if k < 0 { 0.0 } else { 10f64.powf(0.25 * k as f64 - 3.0) };
        for ku in -1..=36 {
            for kl in -1..=36 {
                let (bu, bl) = (grid(ku), grid(kl));
                let model_of = |a: f64, b: f64, c: f64| a + bu * b + bl * c;
                let scale =
                    data.iter().map(|&(y, a, b, c)| y / model_of(a, b, c)).fold(0.0, f64::max);
                if !scale.is_finite() || scale == 0.0 {
                    continue;
                }
                let over: f64 =
                    data.iter().map(|&(y, a, b, c)| (scale * model_of(a, b, c) / y).ln()).sum();
                if best.is_none_or(|(o, ..)| over < o) {
                    best = Some((over, scale, scale * bu, scale * bl));
                }
            }
        }
        let Some((_, cx, cu, cl)) = best else {
            return Err(invalid(
                "samples",
                "no error above 1e-12 or no finite fit",
                "calibration needs samples whose errors the model can explain",
            ));
        };
        let out = Self {
            tolerance,
            state_constant: cx,
            input_constant: cu,
            fast_constant: cl,
            min_substeps,
            max_substeps,
        };
        out.validate()?;
        Ok(out)
    }
}

impl Default for IntegratorSettings {
    fn default() -> Self {
        Self {
            kind: IntegratorKind::Rk4,
            substeps: 4,
            linear_part: LinearPart::Model,
            newton_tolerance: 1e-13,
            newton_max_iterations: 30,
            adaptive: None,
        }
    }
}

impl IntegratorSettings {
    /// Settings for `kind` with `substeps` substeps, other fields default.
    pub fn new(kind: IntegratorKind, substeps: usize) -> Self {
        Self { kind, substeps, ..Self::default() }
    }

    /// Checks the ranges documented on each field.
    pub fn validate(&self) -> Result<()> {
        if self.substeps == 0 {
            return Err(invalid("integrator.substeps", self.substeps, "must be at least 1"));
        }
        if !(self.newton_tolerance > 0.0 && self.newton_tolerance <= 1e-2) {
            return Err(invalid(
                "integrator.newton_tolerance",
                self.newton_tolerance,
                "must be in (0, 1e-2]",
            ));
        }
        if self.newton_max_iterations == 0 {
            return Err(invalid(
                "integrator.newton_max_iterations",
                self.newton_max_iterations,
                "must be at least 1",
            ));
        }
        if let Some(a) = &self.adaptive {
            a.validate()?;
            if self.kind == IntegratorKind::ImplicitMidpoint {
                return Err(invalid(
                    "integrator.adaptive",
                    "ImplicitMidpoint",
                    "state-adapted substeps need an explicit method (RK4, LawsonRk4)",
                ));
            }
            if self.substeps < a.min_substeps || self.substeps > a.max_substeps {
                return Err(invalid(
                    "integrator.substeps",
                    self.substeps,
                    "must lie in [adaptive.min_substeps, adaptive.max_substeps]",
                ));
            }
        }
        Ok(())
    }

    /// The substep counts an integrator built from these settings can run:
    /// `[min_substeps, max_substeps]` when adaptive, else `substeps` only.
    fn count_range(&self) -> (usize, usize) {
        match &self.adaptive {
            Some(a) => (a.min_substeps, a.max_substeps),
            None => (self.substeps, self.substeps),
        }
    }
}

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
        check_dim("a rows", self.nx, a.nrows())?;
        check_dim("a columns", self.nx, a.ncols())?;
        check_dim("b rows", self.nx, b.nrows())?;
        check_dim("b columns", self.nu, b.ncols())?;
        self.run(model, x0, u, true, false)?;
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
        self.calls += 1;
        self.x.copy_from_slice(x0);
        if sens {
            self.s.fill(0.0);
            for i in 0..self.nx {
                self.s[(i, i)] = 1.0;
            }
        }
        for n in 0..self.substeps {
            match self.kind {
                IntegratorKind::ImplicitMidpoint => self.midpoint_substep(model, u, sens)?,
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

    /// Evaluates stage `j` at `(xs, u)` (and its sensitivity at `sx`).
    fn stage<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        j: usize,
        sens: bool,
        tape: Option<usize>,
    ) -> Result<()> {
        // the model's own `g = f − Lx`, `∂f/∂x − L` when `L` is its linear part (saves a
        // copy of `W` into the Jacobian and its subtraction at every stage)
        let remainder = sens
            && self.model_linear_part
            && model.remainder_and_jacobians(
                &self.xs,
                u,
                &mut self.k[j],
                &mut self.fx,
                &mut self.fu,
            );
        if !remainder {
            if sens {
                model.rhs_and_jacobians(&self.xs, u, &mut self.k[j], &mut self.fx, &mut self.fu);
            } else {
                model.rhs(&self.xs, u, &mut self.k[j]);
            }
            if let Some(lw) = &self.lawson {
                lw.l_op.apply_vec(&mut self.k[j], &self.xs, -1.0, true);
            }
        }
        if !all_finite(&self.k[j]) {
            return Err(OcpError::NonFiniteDynamics { stage: "rhs" });
        }
        // stage 1 reads the substep's `S` in place (no copy into `sx`)
        let sx = if j == 0 { &self.s } else { &self.sx };
        if let Some(base) = tape {
            self.tape_x[base + j].copy_from_slice(&self.xs);
            self.tape_s[base + j].copy_from(sx);
        }
        if sens {
            if !remainder {
                if let Some(lw) = &self.lawson {
                    self.fx -= &lw.l;
                }
            }
            // a NaN/∞ in the Jacobians propagates into the sensitivities, checked once per interval
            crate::la::mul_right_t(&mut self.ks[j], sx, &self.fx, &mut self.rows);
            for c in 0..self.nu {
                for i in 0..self.nx {
                    self.ks[j][(self.nx + c, i)] += self.fu[(i, c)];
                }
            }
        }
        Ok(())
    }

    fn explicit_substep<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        sens: bool,
        tape: Option<usize>,
    ) -> Result<()> {
        let h = self.h;
        let sens = sens || tape.is_some();
        // stage 1: X1 = x (its sensitivity is `S` itself, read in place by `stage`)
        self.xs.copy_from_slice(&self.x);
        self.stage(model, u, 0, sens, tape)?;
        // E x, E k1 (and E S, E K1) serve stages 2 to 4 and the update, so that E² is never
        // applied: 4 propagator products per substep instead of 6
        Self::pow_vec(&self.lawson, Pow::E1, &mut self.ex, &self.x, 1.0, false);
        Self::pow_vec(&self.lawson, Pow::E1, &mut self.ek1, &self.k[0], 1.0, false);
        if sens {
            Self::pow_mat(&self.lawson, Pow::E1, &mut self.es, &self.s, 1.0, false);
            Self::pow_mat(&self.lawson, Pow::E1, &mut self.eks, &self.ks[0], 1.0, false);
        }
        // stage 2: X2 = E (x + h/2 k1) = Ex + h/2 Ek1
        lincomb(&mut self.xs, &self.ex, 0.5 * h, &self.ek1);
        if sens {
            lincomb(self.sx.as_mut_slice(), self.es.as_slice(), 0.5 * h, self.eks.as_slice());
        }
        self.stage(model, u, 1, sens, tape)?;
        // stage 3: X3 = E x + h/2 k2
        lincomb(&mut self.xs, &self.ex, 0.5 * h, &self.k[1]);
        if sens {
            lincomb(self.sx.as_mut_slice(), self.es.as_slice(), 0.5 * h, self.ks[1].as_slice());
        }
        self.stage(model, u, 2, sens, tape)?;
        // stage 4: X4 = E² x + h E k3 = E (Ex + h k3)
        lincomb(&mut self.t, &self.ex, h, &self.k[2]);
        Self::pow_vec(&self.lawson, Pow::E1, &mut self.xs, &self.t, 1.0, false);
        if sens {
            lincomb(self.tm.as_mut_slice(), self.es.as_slice(), h, self.ks[2].as_slice());
            Self::pow_mat(&self.lawson, Pow::E1, &mut self.sx, &self.tm, 1.0, false);
        }
        self.stage(model, u, 3, sens, tape)?;
        // x⁺ = E²(x + h/6 k1) + h/3 E(k2 + k3) + h/6 k4
        //    = E (Ex + h/6 Ek1 + h/3 (k2 + k3)) + h/6 k4
        for i in 0..self.nx {
            self.t[i] =
                self.ex[i] + h / 6.0 * self.ek1[i] + h / 3.0 * (self.k[1][i] + self.k[2][i]);
        }
        Self::pow_vec(&self.lawson, Pow::E1, &mut self.x, &self.t, 1.0, false);
        axpy(&mut self.x, h / 6.0, &self.k[3]);
        if sens {
            let (tm, es, eks, k2, k3) = (
                self.tm.as_mut_slice(),
                self.es.as_slice(),
                self.eks.as_slice(),
                self.ks[1].as_slice(),
                self.ks[2].as_slice(),
            );
            for i in 0..tm.len() {
                tm[i] = es[i] + h / 6.0 * eks[i] + h / 3.0 * (k2[i] + k3[i]);
            }
            Self::pow_mat(&self.lawson, Pow::E1, &mut self.s, &self.tm, 1.0, false);
            axpy(self.s.as_mut_slice(), h / 6.0, self.ks[3].as_slice());
        }
        Ok(())
    }

    /// Factorises `lu = I − h/2 fx` in place.
    fn factor_newton(&mut self) -> Result<()> {
        let nx = self.nx;
        self.lu.copy_from(&self.fx);
        self.lu *= -0.5 * self.h;
        for i in 0..nx {
            self.lu[(i, i)] += 1.0;
        }
        let (r, c) = self.lu.shape();
        let view = faer::MatMut::from_column_major_slice_mut(self.lu.as_mut_slice(), r, c);
        let _ = lu_factor::lu_in_place(
            view,
            &mut self.perm,
            &mut self.perm_inv,
            Par::Seq,
            MemStack::new(&mut self.mem),
            Default::default(),
        );
        for i in 0..nx {
            let d = self.lu[(i, i)];
            if d == 0.0 || !d.is_finite() {
                return Err(OcpError::Singular { what: "implicit midpoint Newton matrix" });
            }
        }
        Ok(())
    }

    /// Solves with the factorised Newton matrix, in place, for `rhs` (`nx × m`, column-major).
    fn solve_newton(
        lu: &DMatrix<f64>,
        perm: &[usize],
        perm_inv: &[usize],
        mem: &mut MemBuffer,
        rhs: &mut [f64],
        m: usize,
    ) {
        let n = lu.nrows();
        let lu_ref = faer::MatRef::from_column_major_slice(lu.as_slice(), n, n);
        // SAFETY-free: the permutation arrays come from lu_in_place.
        let p = faer::perm::PermRef::new_checked(perm, perm_inv, n);
        lu_solve::solve_in_place_with_conj(
            lu_ref,
            lu_ref,
            p,
            Conj::No,
            faer::MatMut::from_column_major_slice_mut(rhs, n, m),
            Par::Seq,
            MemStack::new(mem),
        );
    }

    fn midpoint_substep<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        sens: bool,
    ) -> Result<()> {
        let h = self.h;
        let nx = self.nx;
        // initial guess: explicit half step
        model.rhs(&self.x, u, &mut self.k[0]);
        if !all_finite(&self.k[0]) {
            return Err(OcpError::NonFiniteDynamics { stage: "rhs" });
        }
        self.xs.copy_from_slice(&self.x);
        axpy(&mut self.xs, 0.5 * h, &self.k[0]);
        let mut converged = false;
        let mut residual = f64::INFINITY;
        let mut it = 0;
        while it <= self.newton_max_iterations {
            model.rhs(&self.xs, u, &mut self.k[0]);
            if !all_finite(&self.k[0]) {
                return Err(OcpError::NonFiniteDynamics { stage: "rhs" });
            }
            for i in 0..nx {
                self.t[i] = self.xs[i] - self.x[i] - 0.5 * h * self.k[0][i];
            }
            residual = norm_inf(&self.t);
            if residual <= self.newton_tolerance * (1.0 + norm_inf(&self.xs)) {
                converged = true;
                break;
            }
            if it == self.newton_max_iterations {
                break;
            }
            model.jacobians(&self.xs, u, &mut self.fx, &mut self.fu);
            if !all_finite(self.fx.as_slice()) {
                return Err(OcpError::NonFiniteDynamics { stage: "jacobian" });
            }
            self.factor_newton()?;
            Self::solve_newton(&self.lu, &self.perm, &self.perm_inv, &mut self.mem, &mut self.t, 1);
            for i in 0..nx {
                self.xs[i] -= self.t[i];
            }
            if !all_finite(&self.xs) {
                return Err(OcpError::NonFiniteDynamics { stage: "state" });
            }
            it += 1;
        }
        if !converged {
            return Err(OcpError::NewtonFailed { iterations: it, residual });
        }
        if sens {
            model.jacobians(&self.xs, u, &mut self.fx, &mut self.fu);
            if !all_finite(self.fx.as_slice()) || !all_finite(self.fu.as_slice()) {
                return Err(OcpError::NonFiniteDynamics { stage: "jacobian" });
            }
            self.factor_newton()?;
            // (I − h/2 fx) ∂m/∂z = S + h/2 [0 | fu];  S⁺ = 2 ∂m/∂z − S
            let m = self.nx + self.nu;
            for j in 0..m {
                for i in 0..nx {
                    self.tcm[(i, j)] = self.s[(j, i)];
                }
            }
            axpy(&mut self.tcm.as_mut_slice()[nx * nx..], 0.5 * h, self.fu.as_slice());
            Self::solve_newton(
                &self.lu,
                &self.perm,
                &self.perm_inv,
                &mut self.mem,
                self.tcm.as_mut_slice(),
                m,
            );
            for j in 0..m {
                for i in 0..nx {
                    self.tm[(j, i)] = self.tcm[(i, j)];
                }
            }
            self.s *= -1.0;
            axpy(self.s.as_mut_slice(), 2.0, self.tm.as_slice());
        }
        for i in 0..nx {
            self.x[i] = 2.0 * self.xs[i] - self.x[i];
        }
        Ok(())
    }

    /// Backward sweep over the tape: accumulates `Σ Ŝⱼᵀ (k̄ⱼ·∇²f) Ŝⱼ` into `out`.
    fn backward<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        lambda: &[f64],
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        let h = self.h;
        let nx = self.nx;
        let nz = nx + self.nu;
        out.fill(0.0);
        self.lbar.copy_from_slice(lambda);
        for n in (0..self.substeps).rev() {
            let base = 4 * n;
            // k̄4 = h/6 λ̄
            for i in 0..nx {
                self.kbar[3][i] = h / 6.0 * self.lbar[i];
            }
            self.stage_adjoint(model, u, base, 3)?;
            // k̄3 = Eᵀ(h/3 λ̄ + h X̄4)
            for i in 0..nx {
                self.t[i] = h / 3.0 * self.lbar[i] + h * self.xbar[3][i];
            }
            Self::pow_t_vec(&self.lawson, Pow::E1, &mut self.kbar[2], &self.t, 1.0, false);
            self.stage_adjoint(model, u, base, 2)?;
            // k̄2 = h/3 Eᵀλ̄ + h/2 X̄3
            Self::pow_t_vec(&self.lawson, Pow::E1, &mut self.kbar[1], &self.lbar, h / 3.0, false);
            let (kb, xb) = (&mut self.kbar[1], &self.xbar[2]);
            axpy(kb, 0.5 * h, xb);
            self.stage_adjoint(model, u, base, 1)?;
            // k̄1 = h/6 E²ᵀ λ̄ + h/2 Eᵀ X̄2
            Self::pow_t_vec(&self.lawson, Pow::E2, &mut self.kbar[0], &self.lbar, h / 6.0, false);
            Self::pow_t_vec(&self.lawson, Pow::E1, &mut self.kbar[0], &self.xbar[1], 0.5 * h, true);
            self.stage_adjoint(model, u, base, 0)?;
            // λ̄ ← E²ᵀλ̄ + X̄1 + Eᵀ(X̄2 + X̄3) + E²ᵀ X̄4
            for i in 0..nx {
                self.t[i] = self.lbar[i] + self.xbar[3][i];
            }
            Self::pow_t_vec(&self.lawson, Pow::E2, &mut self.lbar, &self.t, 1.0, false);
            axpy(&mut self.lbar, 1.0, &self.xbar[0]);
            for i in 0..nx {
                self.t[i] = self.xbar[1][i] + self.xbar[2][i];
            }
            Self::pow_t_vec(&self.lawson, Pow::E1, &mut self.lbar, &self.t, 1.0, true);
            // Hessian contributions of the four stages of this substep
            for j in 0..4 {
                model.weighted_hessian(&self.tape_x[base + j], u, &self.kbar[j], &mut self.whess);
                if !all_finite(self.whess.as_slice()) {
                    return Err(OcpError::NonFiniteDynamics { stage: "hessian" });
                }
                self.shat.fill(0.0);
                for c in 0..nz {
                    for r in 0..nx {
                        self.shat[(r, c)] = self.tape_s[base + j][(c, r)];
                    }
                }
                for i in nx..nz {
                    self.shat[(i, i)] = 1.0;
                }
                gemm(&mut self.zz, &self.whess, &self.shat, 1.0, false);
                crate::la::gemm_tn(out, &self.shat, &self.zz, 1.0, true);
            }
        }
        // symmetrise against round-off
        for i in 0..nz {
            for j in 0..i {
                let v = 0.5 * (out[(i, j)] + out[(j, i)]);
                out[(i, j)] = v;
                out[(j, i)] = v;
            }
        }
        Ok(())
    }

    /// `X̄ⱼ = (∂g/∂x)ᵀ(Xⱼ) k̄ⱼ`.
    fn stage_adjoint<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        base: usize,
        j: usize,
    ) -> Result<()> {
        model.jacobians(&self.tape_x[base + j], u, &mut self.fx, &mut self.fu);
        if let Some(lw) = &self.lawson {
            self.fx -= &lw.l;
        }
        if !all_finite(self.fx.as_slice()) {
            return Err(OcpError::NonFiniteDynamics { stage: "jacobian" });
        }
        gemv_t(&mut self.xbar[j], &self.fx, &self.kbar[j], 1.0, false);
        Ok(())
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
