//! The [`Dynamics`] trait: an ODE right-hand side `ẋ = f(x, u)` with its derivatives.

use nalgebra::DMatrix;

/// An explicit ODE `ẋ = f(x, u)` with `x ∈ R^nx`, `u ∈ R^nu` (the model `h(q̇, q, u) = 0`
/// of eq. 33 solved for `q̇`).
///
/// Implementations write into caller buffers and must not allocate: the integrators call
/// them inside the SQP loop. Shapes are guaranteed by the caller (`x.len() == nx`,
/// `u.len() == nu`, `fx` is `nx × nx`, `fu` is `nx × nu`, every buffer is overwritten).
/// A model may return NaN or infinity (e.g. outside its domain); the integrators detect it
/// and the SQP reports [`crate::SqpStatus::NonFiniteDynamics`].
///
/// Models are `Sync` so that the shooting intervals can be integrated in parallel
/// ([`crate::SqpSettings::parallel_intervals`]).
pub trait Dynamics: Sync {
    /// State dimension `nx`.
    fn nx(&self) -> usize;
    /// Control dimension `nu`.
    fn nu(&self) -> usize;
    /// `xdot = f(x, u)`.
    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]);
    /// `fx = ∂f/∂x`, `fu = ∂f/∂u` at `(x, u)`.
    fn jacobians(&self, x: &[f64], u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>);
    /// `xdot = f(x, u)`, `fx = ∂f/∂x`, `fu = ∂f/∂u` at the same point (an integrator stage
    /// with sensitivities needs all three). The default calls [`Dynamics::rhs`] and
    /// [`Dynamics::jacobians`]; a model may share work between them (a quadratic model
    /// `f = Wx + N(x)x + Bu` has `f = ½(∂f/∂x + W)x + Bu` by Euler's identity, one
    /// matrix–vector product instead of a pass over its tensor).
    fn rhs_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        xdot: &mut [f64],
        fx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) {
        self.rhs(x, u, xdot);
        self.jacobians(x, u, fx, fu);
    }
    /// The stage evaluation of the Lawson integrator with `L` = [`Dynamics::linear_part`]:
    /// `g = f(x, u) − Lx`, `gx = ∂f/∂x − L`, `fu = ∂f/∂u`. Returns `false` when not
    /// implemented (the default, which writes nothing; the integrator then calls
    /// [`Dynamics::rhs_and_jacobians`] and subtracts `L` itself). A model whose linear part
    /// is stored apart from its nonlinear terms saves a copy and a subtraction of `L` per
    /// stage. Must agree with `rhs_and_jacobians` minus `L` up to round-off.
    fn remainder_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        g: &mut [f64],
        gx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) -> bool {
        let _ = (x, u, g, gx, fu);
        false
    }
    /// The stage evaluation of a Lawson trial without sensitivities (a line-search trial needs
    /// only the states): `g = f(x, u) − Lx` with `L` = [`Dynamics::linear_part`]. Returns
    /// `false` when not implemented (the default, which writes nothing; the integrator then
    /// calls [`Dynamics::rhs`] and subtracts `Lx` itself, two products with the linear part
    /// that a model storing it apart skips). Must agree with `rhs` minus `Lx` up to round-off.
    fn remainder(&self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        let _ = (x, u, g);
        false
    }
    /// Whether [`Dynamics::weighted_hessian`] is implemented (needed by the exact-Hessian SQP).
    fn has_second_order(&self) -> bool {
        false
    }
    /// Second-order term `out = Σ_i w_i ∇²f_i(x, u)`, a symmetric `(nx+nu) × (nx+nu)` matrix
    /// ordered `(x, u)`. Only called when [`Dynamics::has_second_order`] is true; the default
    /// writes zeros.
    fn weighted_hessian(&self, x: &[f64], u: &[f64], w: &[f64], out: &mut DMatrix<f64>) {
        let _ = (x, u, w);
        out.fill(0.0);
    }
    /// A constant stiff linear part `L` of `f` (e.g. the modal `W` of `ẋ = Wx + N(x)x + Bu`),
    /// used by the Lawson integrator with [`crate::LinearPart::Model`]. `None` by default.
    fn linear_part(&self) -> Option<DMatrix<f64>> {
        None
    }
}

impl<D: Dynamics + ?Sized> Dynamics for &D {
    fn nx(&self) -> usize {
        (**self).nx()
    }
    fn nu(&self) -> usize {
        (**self).nu()
    }
    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
        (**self).rhs(x, u, xdot)
    }
    fn jacobians(&self, x: &[f64], u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        (**self).jacobians(x, u, fx, fu)
    }
    fn rhs_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        xdot: &mut [f64],
        fx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) {
        (**self).rhs_and_jacobians(x, u, xdot, fx, fu)
    }
    fn remainder_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        g: &mut [f64],
        gx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) -> bool {
        (**self).remainder_and_jacobians(x, u, g, gx, fu)
    }
    fn remainder(&self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        (**self).remainder(x, u, g)
    }
    fn has_second_order(&self) -> bool {
        (**self).has_second_order()
    }
    fn weighted_hessian(&self, x: &[f64], u: &[f64], w: &[f64], out: &mut DMatrix<f64>) {
        (**self).weighted_hessian(x, u, w, out)
    }
    fn linear_part(&self) -> Option<DMatrix<f64>> {
        (**self).linear_part()
    }
}
