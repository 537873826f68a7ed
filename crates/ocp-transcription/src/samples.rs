//! Canonical test models: a linear system, the cart-pole (NMPC benchmark) and a synthetic
//! model with the modal ROM's structure `ẋ = Wx + N(x)x + Bu`.

use crate::dynamics::Dynamics;
use crate::error::OcpError;
use crate::error::{check_dim, invalid, Result};
use crate::integrator::Integrator;
use crate::integrator::IntegratorSettings;
use crate::ocp::Ocp;
use crate::quadratic::QuadraticTerms;
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// The seeded generator of the samples, tests and benches: `rand_chacha`'s ChaCha8 from a
/// 64-bit seed, the workspace's one generator (the same as `intrinsic_beam`'s
/// `samples::random::seeded`; this crate depends on no other crate of the workspace). Its
/// stream is fixed by the seed alone, on every platform and in every release of the crate.
///
/// ```
/// use ocp_transcription::samples::seeded;
/// use rand::Rng;
/// let draw = |seed| seeded(seed).random_range(-1.0..1.0);
/// assert_eq!(draw(7), draw(7));
/// ```
pub fn seeded(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Linear time-invariant model `ẋ = A x + B u`.
#[derive(Clone, Debug)]
pub struct LinearModel {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
}

impl LinearModel {
    /// `A` is `nx × nx`, `B` is `nx × nu`.
    pub fn new(a: DMatrix<f64>, b: DMatrix<f64>) -> Result<Self> {
        check_dim("A columns", a.nrows(), a.ncols())?;
        check_dim("B rows", a.nrows(), b.nrows())?;
        Ok(Self { a, b })
    }

    /// A chain of `n` unit masses joined by unit springs (first one tied to a wall), with
    /// light damping, forces on the first `nu` masses: `nx = 2n`, `x = (positions, velocities)`.
    pub fn spring_chain(n: usize, nu: usize) -> Self {
        let nx = 2 * n;
        let mut a = DMatrix::zeros(nx, nx);
        let mut b = DMatrix::zeros(nx, nu);
        for i in 0..n {
            a[(i, n + i)] = 1.0;
            let left = 1.0;
            let right = if i + 1 < n { 1.0 } else { 0.0 };
            a[(n + i, i)] = -(left + right);
            if i > 0 {
                a[(n + i, i - 1)] = 1.0;
            }
            if i + 1 < n {
                a[(n + i, i + 1)] = 1.0;
            }
            a[(n + i, n + i)] = -0.05;
        }
        for k in 0..nu.min(n) {
            b[(n + k, k)] = 1.0;
        }
        Self { a, b }
    }
}

impl Dynamics for LinearModel {
    fn nx(&self) -> usize {
        self.a.nrows()
    }
    fn nu(&self) -> usize {
        self.b.ncols()
    }
    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
        crate::la::gemv(xdot, &self.a, x, 1.0, false);
        crate::la::gemv(xdot, &self.b, u, 1.0, true);
    }
    fn jacobians(&self, _x: &[f64], _u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        fx.copy_from(&self.a);
        fu.copy_from(&self.b);
    }
    fn has_second_order(&self) -> bool {
        true
    }
    fn linear_part(&self) -> Option<DMatrix<f64>> {
        Some(self.a.clone())
    }
}

/// Scalars the cart-pole right-hand side is written for (`f64` and hyper-dual numbers).
trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    fn cst(v: f64) -> Self;
    fn sin(self) -> Self;
    fn cos(self) -> Self;
}

impl Scalar for f64 {
    fn cst(v: f64) -> Self {
        v
    }
    fn sin(self) -> Self {
        f64::sin(self)
    }
    fn cos(self) -> Self {
        f64::cos(self)
    }
}

/// Hyper-dual number `re + a ε₁ + b ε₂ + ab ε₁ε₂` (exact first and second derivatives).
#[derive(Clone, Copy, Debug)]
struct HyperDual {
    re: f64,
    a: f64,
    b: f64,
    ab: f64,
}

impl HyperDual {
    fn chain(self, g0: f64, g1: f64, g2: f64) -> Self {
        Self { re: g0, a: g1 * self.a, b: g1 * self.b, ab: g1 * self.ab + g2 * self.a * self.b }
    }
}

impl Add for HyperDual {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self { re: self.re + o.re, a: self.a + o.a, b: self.b + o.b, ab: self.ab + o.ab }
    }
}
impl Sub for HyperDual {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self { re: self.re - o.re, a: self.a - o.a, b: self.b - o.b, ab: self.ab - o.ab }
    }
}
impl Mul for HyperDual {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        Self {
            re: self.re * o.re,
            a: self.re * o.a + self.a * o.re,
            b: self.re * o.b + self.b * o.re,
            ab: self.re * o.ab + self.a * o.b + self.b * o.a + self.ab * o.re,
        }
    }
}
impl Div for HyperDual {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let r = 1.0 / o.re;
        self * o.chain(r, -r * r, 2.0 * r * r * r)
    }
}
impl Neg for HyperDual {
    type Output = Self;
    fn neg(self) -> Self {
        Self { re: -self.re, a: -self.a, b: -self.b, ab: -self.ab }
    }
}
impl Scalar for HyperDual {
    fn cst(v: f64) -> Self {
        Self { re: v, a: 0.0, b: 0.0, ab: 0.0 }
    }
    fn sin(self) -> Self {
        let (s, c) = self.re.sin_cos();
        self.chain(s, c, -s)
    }
    fn cos(self) -> Self {
        let (s, c) = self.re.sin_cos();
        self.chain(c, -s, -c)
    }
}

/// Cart-pole (the acados/NMPC swing-up benchmark): `x = (p, θ, v, ω)` with `θ = 0` upright,
/// `u = F` the horizontal force on the cart.
///
/// `v̇ = (−m l sinθ ω² + m g cosθ sinθ + F) / (M + m − m cos²θ)`,
/// `ω̇ = (−m l cosθ sinθ ω² + F cosθ + (M + m) g sinθ) / (l (M + m − m cos²θ))`.
/// Derivatives (first and second) are exact, by hyper-dual numbers.
#[derive(Clone, Debug)]
pub struct CartPole {
    /// Cart mass `M` (kg).
    pub cart_mass: f64,
    /// Pole tip mass `m` (kg).
    pub pole_mass: f64,
    /// Pole length `l` (m).
    pub length: f64,
    /// Gravity `g` (m/s²).
    pub gravity: f64,
}

impl Default for CartPole {
    /// acados' parameters: `M = 1`, `m = 0.1`, `l = 0.8`, `g = 9.81`.
    fn default() -> Self {
        Self { cart_mass: 1.0, pole_mass: 0.1, length: 0.8, gravity: 9.81 }
    }
}

impl CartPole {
    fn eval<T: Scalar>(&self, x: [T; 4], f: T) -> [T; 4] {
        let (mm, m, l, g) = (
            T::cst(self.cart_mass),
            T::cst(self.pole_mass),
            T::cst(self.length),
            T::cst(self.gravity),
        );
        let (s, c) = (x[1].sin(), x[1].cos());
        let w = x[3];
        let den = mm + m - m * c * c;
        let vdot = (-(m * l * s * w * w) + m * g * c * s + f) / den;
        let wdot = (-(m * l * c * s * w * w) + f * c + (mm + m) * g * s) / (l * den);
        [x[2], w, vdot, wdot]
    }

    fn seeded(&self, x: &[f64], u: &[f64], i: usize, j: Option<usize>) -> [HyperDual; 4] {
        let mut z = [HyperDual::cst(0.0); 5];
        for k in 0..4 {
            z[k] = HyperDual::cst(x[k]);
        }
        z[4] = HyperDual::cst(u[0]);
        z[i].a = 1.0;
        if let Some(j) = j {
            z[j].b = 1.0;
        }
        self.eval([z[0], z[1], z[2], z[3]], z[4])
    }
}

impl Dynamics for CartPole {
    fn nx(&self) -> usize {
        4
    }
    fn nu(&self) -> usize {
        1
    }
    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
        let r = self.eval([x[0], x[1], x[2], x[3]], u[0]);
        xdot.copy_from_slice(&r);
    }
    fn jacobians(&self, x: &[f64], u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        for i in 0..5 {
            let r = self.seeded(x, u, i, None);
            for k in 0..4 {
                if i < 4 {
                    fx[(k, i)] = r[k].a;
                } else {
                    fu[(k, 0)] = r[k].a;
                }
            }
        }
    }
    fn has_second_order(&self) -> bool {
        true
    }
    fn weighted_hessian(&self, x: &[f64], u: &[f64], w: &[f64], out: &mut DMatrix<f64>) {
        for i in 0..5 {
            for j in i..5 {
                let r = self.seeded(x, u, i, Some(j));
                let v: f64 = (0..4).map(|k| w[k] * r[k].ab).sum();
                out[(i, j)] = v;
                out[(j, i)] = v;
            }
        }
    }
}

/// States `x_0 … x_N` and controls `u_0 … u_{N−1}` of a plan.
pub type Trajectory = (Vec<DVector<f64>>, Vec<DVector<f64>>);

/// The oracle of the linear-quadratic problems: the discrete-time Riccati recursion on the
/// integrator's own `A = ∂Φ/∂x`, `B = ∂Φ/∂u` of one interval (at `x = 0`, `u = 0`, exact
/// for a linear `model`) with the OCP's trapezoidal node weights (`½Δt Q` at the first node,
/// `Δt Q` inside, `Q_N` at the end, `Δt R`), and the closed-loop plan from `x0` under its
/// gains. Without bounds this is the exact minimiser of the transcribed problem, so the SQP
/// must reproduce it to solver precision.
pub fn riccati_plan<D: Dynamics + ?Sized>(
    model: &D,
    ocp: &Ocp,
    settings: &IntegratorSettings,
    x0: &DVector<f64>,
) -> Result<Trajectory> {
    let (nx, nu, n, dt) = (ocp.nx(), ocp.nu(), ocp.intervals, ocp.interval());
    check_dim("x0", nx, x0.len())?;
    let mut int = Integrator::new(model, settings, dt)?;
    let (mut a, mut b, mut xe) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu), vec![0.0; nx]);
    int.integrate_with_sensitivities(
        model,
        &vec![0.0; nx],
        &vec![0.0; nu],
        &mut xe,
        &mut a,
        &mut b,
    )?;
    let rd = &ocp.r * dt;
    let mut p = &ocp.q * (0.5 * dt) + &ocp.terminal;
    let mut gains = vec![DMatrix::zeros(nu, nx); n];
    for k in (0..n).rev() {
        let btp = b.transpose() * &p;
        let gain = (&rd + &btp * &b)
            .cholesky()
            .ok_or(OcpError::Singular { what: "the Riccati recursion's R + BᵀPB" })?
            .solve(&(&btp * &a));
        let qk = &ocp.q * if k == 0 { 0.5 * dt } else { dt };
        p = qk + a.transpose() * &p * (&a - &b * &gain);
        p = 0.5 * (&p + p.transpose());
        gains[k] = gain;
    }
    let mut xs = vec![x0.clone()];
    let mut us = Vec::new();
    for gain in &gains {
        let u = -gain * xs.last().expect("x0 is the first state");
        xs.push(&a * xs.last().expect("x0 is the first state") + &b * &u);
        us.push(u);
    }
    Ok((xs, us))
}

/// Largest relative deviation `|FD − exact| / (1 + |exact|)` of an integrator pass's
/// sensitivities `A = ∂Φ/∂x`, `B = ∂Φ/∂u` at `(x, u)` from central differences with step
/// `1e-6` (truncation `~ε²‖Φ'''‖ ≈ 1e-12`, round-off `~1e-16/ε ≈ 1e-10`; a missing term of
/// order `h` shows as `~1e-2`).
pub fn fd_sensitivity_error<D: Dynamics + ?Sized>(
    int: &mut Integrator,
    model: &D,
    x: &[f64],
    u: &[f64],
) -> Result<f64> {
    let (nx, nu) = (model.nx(), model.nu());
    let (mut xe, mut xp, mut xm) = (vec![0.0; nx], vec![0.0; nx], vec![0.0; nx]);
    let mut a = DMatrix::zeros(nx, nx);
    let mut b = DMatrix::zeros(nx, nu);
    int.integrate_with_sensitivities(model, x, u, &mut xe, &mut a, &mut b)?;
    let eps = 1e-6;
    let mut err = 0.0_f64;
    for j in 0..nx + nu {
        let (mut x1, mut u1, mut x2, mut u2) = (x.to_vec(), u.to_vec(), x.to_vec(), u.to_vec());
        if j < nx {
            x1[j] += eps;
            x2[j] -= eps;
        } else {
            u1[j - nx] += eps;
            u2[j - nx] -= eps;
        }
        int.integrate(model, &x1, &u1, &mut xp)?;
        int.integrate(model, &x2, &u2, &mut xm)?;
        for i in 0..nx {
            let an = if j < nx { a[(i, j)] } else { b[(i, j - nx)] };
            err = err.max(((xp[i] - xm[i]) / (2.0 * eps) - an).abs() / (1.0 + an.abs()));
        }
    }
    Ok(err)
}

/// The cart-pole whose dynamics return NaN (in `ṗ̇`) once the cart leaves `|p| ≤ 0.5`: a model
/// with a bounded domain, for checking that non-finite dynamics end a solve in a status, not a
/// panic. Jacobians are the cart-pole's.
#[derive(Clone, Debug, Default)]
pub struct Fragile(pub CartPole);

impl Dynamics for Fragile {
    fn nx(&self) -> usize {
        4
    }
    fn nu(&self) -> usize {
        1
    }
    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
        self.0.rhs(x, u, xdot);
        if x[0].abs() > 0.5 {
            xdot[2] = f64::NAN;
        }
    }
    fn jacobians(&self, x: &[f64], u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        self.0.jacobians(x, u, fx, fu)
    }
}

/// A synthetic model with the modal ROM's structure (paper eqs. 14–21, theory.md §5):
/// `ẋ = W x + N(x) x + B u` with `N(x) = Σ_l x_l Γ_l` linear in `x`, every `Γ_l` sparse and
/// skew-symmetric (so `xᵀ N(x) x = 0`, the ROM's energy identity), `W` block diagonal with
/// 2 × 2 oscillator blocks `[[−2ζω, −ω], [ω, 0]]` (two rigid pairs with `ω = 0`, the rest
/// with frequencies growing quadratically up to `omega_max`), plus one extra state when `nx`
/// is odd (a slow, purely nonlinear coordinate like the ROM's quaternion coefficients).
#[derive(Clone, Debug)]
pub struct ModalLike {
    w: DMatrix<f64>,
    /// Nonzeros of `W`, `(i, j, v)`.
    w_entries: Vec<(usize, usize, f64)>,
    b: DMatrix<f64>,
    /// `(i, l, j, v)`: `(N(x)x)_i += v x_l x_j`.
    gamma: Vec<(usize, usize, usize, f64)>,
    /// The same terms with their Jacobian map (the fast kernel).
    quad: QuadraticTerms,
    /// `(m, nq2, nξ)` for [`ModalLike::rom_like`].
    blocks: Option<(usize, usize, usize)>,
}

/// Nonzeros of a dense matrix, `(i, j, v)`.
fn entries_of(w: &DMatrix<f64>) -> Vec<(usize, usize, f64)> {
    let mut out = Vec::new();
    for j in 0..w.ncols() {
        for i in 0..w.nrows() {
            if w[(i, j)] != 0.0 {
                out.push((i, j, w[(i, j)]));
            }
        }
    }
    out
}

impl ModalLike {
    /// `nx ≥ 4` states, `nu ≥ 1` inputs, highest frequency `omega_max` (rad/s),
    /// `gamma_scale` the size of the `Γ` entries (`|v| ≤ gamma_scale`), deterministic `seed`.
    /// Each `Γ_l` has 3 skew pairs; damping ratio 0.5 %.
    pub fn new(nx: usize, nu: usize, omega_max: f64, gamma_scale: f64, seed: u64) -> Result<Self> {
        if nx < 4 {
            return Err(invalid("nx", nx, "ModalLike needs at least 4 states"));
        }
        if nu == 0 {
            return Err(invalid("nu", nu, "ModalLike needs at least 1 input"));
        }
        if !(omega_max > 0.0 && omega_max.is_finite()) {
            return Err(invalid("omega_max", omega_max, "must be positive and finite"));
        }
        let mut rng = seeded(seed);
        let pairs = nx / 2;
        let mut w = DMatrix::zeros(nx, nx);
        for p in 0..pairs {
            let omega =
                if p < 2 { 0.0 } else { omega_max * ((p - 1) as f64 / (pairs - 2) as f64).powi(2) };
            let (i, j) = (2 * p, 2 * p + 1);
            w[(i, i)] = -2.0 * 0.005 * omega;
            w[(i, j)] = -omega;
            w[(j, i)] = omega;
        }
        let mut gamma = Vec::new();
        for l in 0..nx {
            for _ in 0..3 {
                let i = rng.random_range(0..nx);
                let mut j = rng.random_range(0..nx);
                if j == i {
                    j = (i + 1) % nx;
                }
                let v = gamma_scale * rng.random_range(-1.0..1.0);
                gamma.push((i, l, j, v));
                gamma.push((j, l, i, -v));
            }
        }
        let b = DMatrix::from_fn(nx, nu, |_, _| rng.random_range(-1.0..1.0));
        Ok(Self {
            w_entries: entries_of(&w),
            quad: QuadraticTerms::new(nx, &gamma)?,
            w,
            b,
            gamma,
            blocks: None,
        })
    }

    /// A model with the block structure and sparsity of the paper's 3D modal ROM (augmented
    /// model (29): `x = [q1, q2, qξ]`), measured on `mpc::RomDynamics` of the paper-3d scene
    /// (50 elements per link: `nx = 53 = 20 + 16 + 17`, 1728/1024/1036 entries in
    /// `Γ1/Γ2/Γξ`, median `|Γ|` ≈ 1, 90th percentile ≈ 15–20; the nonlinear Jacobian is
    /// zero in the `(q1,q2) × qξ` and `qξ × q2` blocks and 69–83 % dense in the others, 55 %
    /// overall; `e^{hW/2}` has 12 % nonzeros). Scaled to `nx`: `nξ ≈ 0.32 nx` quaternion
    /// coefficients, `m` velocity modes of which 4 rigid, `nq2 = m − 4`, `m + nq2 + nξ = nx`.
    ///
    /// ```text
    ///   q̇1 = Σ q1 + Ω q2 − q1_l Γ1^l q1 − q2_l Γ2^l q2 + B u
    ///   q̇2 = −Ω q1 + q2_l (Γ2^l)ᵀ q1
    ///   q̇ξ = qξ_l Γξ^l q1
    /// ```
    ///
    /// Every coordinate gets one of 4 symmetry classes (rigid modes one each) and a tensor
    /// entry `(i, j, l)` exists only when the classes satisfy `c_i ⊕ c_j ⊕ c_l = 0` (the
    /// selection rule of a symmetric scene), with the measured fill of the allowed triples;
    /// `Γ1` is skew in `(i, j)` and `Γξ` in `(i, l)`, so `½(|q1|² + |q2|²)` and `|qξ|²` are
    /// conserved without damping and input. `|Γ|` is log-uniform in
    /// `gamma_scale·[10^−1.5, 10^1.5]`. Elastic frequencies grow quadratically from 11.5 rad/s
    /// to `omega_max`; `Σ` is diagonal (every third elastic mode 5 % damped, the others
    /// 0.05 %, rigid modes 1e-3) plus ±1e-4 couplings within a class; `B` acts on `q1`, two
    /// inputs per row. Needs `nx ≥ 8`.
    pub fn rom_like(
        nx: usize,
        nu: usize,
        omega_max: f64,
        gamma_scale: f64,
        seed: u64,
    ) -> Result<Self> {
        if nx < 8 {
            return Err(invalid("nx", nx, "ModalLike::rom_like needs at least 8 states"));
        }
        if nu == 0 {
            return Err(invalid("nu", nu, "ModalLike needs at least 1 input"));
        }
        if !(omega_max > 11.5 && omega_max.is_finite()) {
            return Err(invalid("omega_max", omega_max, "must be finite and above 11.5 rad/s"));
        }
        let mut nxi = ((nx as f64) * 17.0 / 53.0).round() as usize;
        if (nx - nxi) % 2 == 1 {
            nxi -= 1;
        }
        let m = (nx - nxi + 4) / 2;
        let nq2 = m - 4;
        let (o2, ox) = (m, m + nq2);
        let mut rng = seeded(seed);
        // symmetry classes: rigid modes one each, the rest random; q2_p shares its mode's class
        let mut class = vec![0usize; nx];
        for j in 0..m {
            class[j] = if j < 4 { j } else { rng.random_range(0..4) };
        }
        for p in 0..nq2 {
            class[o2 + p] = class[4 + p];
        }
        for i in 0..nxi {
            class[ox + i] = if i == 0 { 0 } else { rng.random_range(0..4) };
        }
        let mut w = DMatrix::zeros(nx, nx);
        for j in 0..m {
            w[(j, j)] = if j < 4 {
                -1e-3
            } else {
                let f = (j - 4) as f64 / (nq2.max(2) - 1) as f64;
                let omega = 11.5 + (omega_max - 11.5) * f * f;
                let zeta = if (j - 4) % 3 == 2 { 0.05 } else { 5e-4 };
                w[(j, o2 + j - 4)] = omega;
                w[(o2 + j - 4, j)] = -omega;
                -2.0 * zeta * omega
            };
        }
        for i in 0..m {
            for j in i + 1..m {
                if class[i] == class[j] && rng.random_range(0.0..1.0) < 0.5 {
                    let v = 1e-4 * rng.random_range(-1.0..1.0);
                    w[(i, j)] = v;
                    w[(j, i)] = v;
                }
            }
        }
        let value = |rng: &mut ChaCha8Rng| {
            let sign = if rng.random_range(0..2) == 0 { -1.0 } else { 1.0 };
            sign * gamma_scale * 10f64.powf(rng.random_range(-1.5..1.5))
        };
        let allowed = |a: usize, b: usize, c: usize| class[a] ^ class[b] ^ class[c] == 0;
        let mut gamma = Vec::new();
        // Γ1: out[i] −= v q1_j q1_l, skew in (i, j)
        for i in 0..m {
            for j in i + 1..m {
                for l in 0..m {
                    if allowed(i, j, l) && rng.random_range(0.0..1.0) < 0.9 {
                        let v = value(&mut rng);
                        gamma.push((i, j, l, -v));
                        gamma.push((j, i, l, v));
                    }
                }
            }
        }
        // Γ2: out[i] −= v q2_j q2_l, out[q2_j] += v q1_i q2_l
        for i in 0..m {
            for j in 0..nq2 {
                for l in 0..nq2 {
                    if allowed(i, o2 + j, o2 + l) && rng.random_range(0.0..1.0) < 0.8 {
                        let v = value(&mut rng);
                        gamma.push((i, o2 + j, o2 + l, -v));
                        gamma.push((o2 + j, i, o2 + l, v));
                    }
                }
            }
        }
        // Γξ: out[ξ_i] += v q1_j ξ_l, skew in (i, l)
        for i in 0..nxi {
            for l in i + 1..nxi {
                for j in 0..m {
                    if allowed(ox + i, j, ox + l) && rng.random_range(0.0..1.0) < 0.76 {
                        let v = value(&mut rng);
                        gamma.push((ox + i, j, ox + l, v));
                        gamma.push((ox + l, j, ox + i, -v));
                    }
                }
            }
        }
        let mut b = DMatrix::zeros(nx, nu);
        for i in 0..m {
            for _ in 0..2.min(nu) {
                b[(i, rng.random_range(0..nu))] = rng.random_range(-1.0..1.0);
            }
        }
        Ok(Self {
            w_entries: entries_of(&w),
            quad: QuadraticTerms::new(nx, &gamma)?,
            w,
            b,
            gamma,
            blocks: Some((m, nq2, nxi)),
        })
    }

    /// `(m, nq2, nξ)`: the sizes of the `q1`, `q2` and `qξ` blocks of a
    /// [`ModalLike::rom_like`] model (`None` for [`ModalLike::new`]).
    pub fn rom_blocks(&self) -> Option<(usize, usize, usize)> {
        self.blocks
    }

    /// A state like the paper's initial condition (rigid rotation at rate `omega0` about
    /// two axes): the first two rigid velocity modes at `1.633·omega0` (the value measured on
    /// the 3D ROM), the reference quaternion coefficient `qξ_0 = 1`, the rest 0. `None` for
    /// [`ModalLike::new`] models.
    pub fn rotating_state(&self, omega0: f64) -> Option<Vec<f64>> {
        let (m, nq2, _) = self.blocks?;
        let mut x = vec![0.0; self.w.nrows()];
        x[0] = 1.633 * omega0;
        x[1] = 1.633 * omega0;
        x[m + nq2] = 1.0;
        Some(x)
    }

    /// Calibration samples of an adaptive substep table
    /// ([`crate::AdaptiveSubsteps::calibrate`]) for a [`ModalLike::rom_like`] model: rotating
    /// states ([`ModalLike::rotating_state`]) of ω0 ∈ {0.25, 0.5, 1, 1.5, 2}, each as is and
    /// with seeded random elastic and quaternion perturbations (±0.1), with u = 0, u random in
    /// [−1, 1] and u = ±5, each input vector of length `nu`. `None` for
    /// [`ModalLike::new`] models.
    pub fn calibration_samples(&self, nu: usize) -> Option<Vec<(Vec<f64>, Vec<f64>)>> {
        let mut rng = seeded(4242);
        let mut out = Vec::new();
        for w in [0.25, 0.5, 1.0, 1.5, 2.0] {
            let x = self.rotating_state(w)?;
            let mut xp = x.clone();
            for v in xp.iter_mut().skip(2) {
                *v += rng.random_range(-0.1..0.1);
            }
            for state in [x, xp] {
                out.push((state.clone(), vec![0.0; nu]));
                out.push((state.clone(), (0..nu).map(|_| rng.random_range(-1.0..1.0)).collect()));
                let sat =
                    (0..nu).map(|_| if rng.random_range(0..2) == 0 { -5.0 } else { 5.0 }).collect();
                out.push((state, sat));
            }
        }
        Some(out)
    }

    /// The paper-sized benchmark model with the ROM's structure ([`ModalLike::rom_like`]):
    /// `nx = 61`, `nu = 5`, frequencies up to 175 rad/s, `gamma_scale = 0.1`. The scale is
    /// calibrated on the real 3D ROM's one-interval Lawson errors at the rotating initial
    /// state of ω0 = 2 with moderate inputs (real: 7.9e-3 / 3.2e-3 / 1.5e-3 at 16 / 20 / 24
    /// substeps; this model: 3e-3 / 1e-3 / 4e-4); the nonlinear Jacobian's spectral radius
    /// there is 19 (real 5.7), its max row sum 54 (real 314).
    pub fn paper_sized_rom() -> Self {
        Self::rom_like(61, 5, 175.0, 0.1, 7).expect("valid constants")
    }

    /// Number of tensor entries (terms `v x_l x_j`).
    pub fn tensor_entries(&self) -> usize {
        self.gamma.len()
    }

    /// The paper-sized benchmark model: `nx = 61`, `nu = 5`, frequencies up to 175 rad/s.
    pub fn paper_sized() -> Self {
        Self::new(61, 5, 175.0, 3.0, 7).expect("valid constants")
    }

    /// `xᵀ N(x) x` (zero by construction, up to round-off).
    pub fn nonlinear_power(&self, x: &[f64]) -> f64 {
        self.gamma.iter().map(|&(i, l, j, v)| x[i] * v * x[l] * x[j]).sum()
    }
}

impl Dynamics for ModalLike {
    fn nx(&self) -> usize {
        self.w.nrows()
    }
    fn nu(&self) -> usize {
        self.b.ncols()
    }
    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
        xdot.fill(0.0);
        for &(i, j, v) in &self.w_entries {
            xdot[i] += v * x[j];
        }
        self.quad.add_rhs(x, xdot);
        crate::la::gemv(xdot, &self.b, u, 1.0, true);
    }
    fn jacobians(&self, x: &[f64], _u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        fx.as_mut_slice().copy_from_slice(self.w.as_slice());
        self.quad.add_jacobian(x, fx.as_mut_slice());
        fu.copy_from(&self.b);
    }
    fn remainder_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        g: &mut [f64],
        gx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) -> bool {
        // gx = ∂(N(x)x)/∂x, and by Euler's identity g = N(x)x + Bu = ½ gx x + Bu
        gx.as_mut_slice().fill(0.0);
        self.quad.add_jacobian(x, gx.as_mut_slice());
        crate::la::gemv(g, gx, x, 0.5, false);
        crate::la::gemv(g, &self.b, u, 1.0, true);
        fu.copy_from(&self.b);
        true
    }
    fn remainder(&self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        // g = f − Wx = N(x)x + Bu
        g.fill(0.0);
        self.quad.add_rhs(x, g);
        crate::la::gemv(g, &self.b, u, 1.0, true);
        true
    }
    fn rhs_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        xdot: &mut [f64],
        fx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) {
        // Euler's identity for the quadratic part: ∂(N(x)x)/∂x · x = 2N(x)x, so
        // f = ½(fx + W)x + Bu
        self.jacobians(x, u, fx, fu);
        crate::la::gemv(xdot, fx, x, 0.5, false);
        for &(i, j, v) in &self.w_entries {
            xdot[i] += 0.5 * v * x[j];
        }
        crate::la::gemv(xdot, &self.b, u, 1.0, true);
    }
    fn has_second_order(&self) -> bool {
        true
    }
    fn weighted_hessian(&self, _x: &[f64], _u: &[f64], w: &[f64], out: &mut DMatrix<f64>) {
        out.fill(0.0);
        for &(i, l, j, v) in &self.gamma {
            out[(l, j)] += w[i] * v;
            out[(j, l)] += w[i] * v;
        }
    }
    fn linear_part(&self) -> Option<DMatrix<f64>> {
        Some(self.w.clone())
    }
}
