//! The simplified Newton iteration of the implicit midpoint rule: the same step and
//! sensitivities as full Newton to the Newton tolerance, and no Jacobian per iteration.

use nalgebra::DMatrix;
use ocp_transcription::samples::ModalLike;
use ocp_transcription::{Dynamics, Integrator, IntegratorKind, IntegratorSettings};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A model that counts its evaluations.
pub(crate) struct Counting<D> {
    inner: D,
    rhs: AtomicUsize,
    jacobians: AtomicUsize,
}

impl<D> Counting<D> {
    pub(crate) fn new(inner: D) -> Self {
        Self { inner, rhs: AtomicUsize::new(0), jacobians: AtomicUsize::new(0) }
    }
    /// `(rhs, jacobians)` since the last call.
    pub(crate) fn take(&self) -> (usize, usize) {
        (self.rhs.swap(0, Ordering::Relaxed), self.jacobians.swap(0, Ordering::Relaxed))
    }
}

impl<D: Dynamics> Dynamics for Counting<D> {
    fn nx(&self) -> usize {
        self.inner.nx()
    }
    fn nu(&self) -> usize {
        self.inner.nu()
    }
    fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
        self.rhs.fetch_add(1, Ordering::Relaxed);
        self.inner.rhs(x, u, xdot)
    }
    fn jacobians(&self, x: &[f64], u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        self.jacobians.fetch_add(1, Ordering::Relaxed);
        self.inner.jacobians(x, u, fx, fu)
    }
}

/// Simplified or full Newton, the factor refreshed by the contraction rule only (the counts
/// below are those of that rule; `refresh_after_first_step` has its own test).
fn settings(simplified: bool, substeps: usize) -> IntegratorSettings {
    IntegratorSettings {
        simplified_newton: simplified,
        refresh_after_first_step: false,
        ..IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, substeps)
    }
}

/// The paper-sized ROM-structured sample (61 states, up to 175 rad/s, so `h ω` = 2.7 per
/// substep of 16 in a 0.25 s interval: the stiff regime of the exact-joints NMPC) from the
/// rotating state with perturbed elastic coordinates and a nonzero input.
pub(crate) fn stiff_case() -> (ModalLike, Vec<f64>, Vec<f64>) {
    let m = ModalLike::paper_sized_rom();
    let mut x = m.rotating_state(1.5).unwrap();
    for (i, v) in x.iter_mut().enumerate().skip(2) {
        *v += 0.05 * ((i as f64) * 0.7).sin();
    }
    let u: Vec<f64> = (0..m.nu()).map(|c| 0.8 * ((c as f64) + 1.0).cos()).collect();
    (m, x, u)
}

pub(crate) fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = 1.0 + a.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    a.iter().zip(b).fold(0.0_f64, |m, (p, q)| m.max((p - q).abs())) / scale
}

/// State and sensitivities of one interval agree between simplified and full Newton to the
/// Newton tolerance (1e-13 per substep, relative), propagated over 16 substeps; a wrong
/// sensitivity (a Jacobian at an unconverged point, or the stale factor) is off by far more.
#[test]
fn simplified_newton_gives_the_full_newton_step() {
    let (m, x, u) = stiff_case();
    let (nx, nu) = (m.nx(), m.nu());
    let mut out = Vec::new();
    for simplified in [true, false] {
        let mut int = Integrator::new(&m, &settings(simplified, 16), 0.25).unwrap();
        let mut xe = vec![0.0; nx];
        let mut a = DMatrix::zeros(nx, nx);
        let mut b = DMatrix::zeros(nx, nu);
        int.integrate_with_sensitivities(&m, &x, &u, &mut xe, &mut a, &mut b).unwrap();
        let mut trial = vec![0.0; nx];
        int.integrate(&m, &x, &u, &mut trial).unwrap();
        out.push((xe, a, b, trial));
    }
    let (s, f) = (&out[0], &out[1]);
    let dx = max_rel(&f.0, &s.0);
    let da = max_rel(f.1.as_slice(), s.1.as_slice());
    let db = max_rel(f.2.as_slice(), s.2.as_slice());
    let dt = max_rel(&f.3, &s.3);
    assert!(dx < 1e-11, "state {dx:e}");
    assert!(dt < 1e-11, "trial state {dt:e}");
    assert!(da < 1e-9, "A {da:e}");
    assert!(db < 1e-9, "B {db:e}");
}

/// A trial integration (no sensitivities) evaluates one Jacobian per interval (the first
/// substep's, for its first factor) when the iteration contracts, where full Newton evaluates
/// one per iteration; with sensitivities, one per substep at the converged midpoint plus the
/// first. The number of right-hand sides stays of the order of full Newton's.
#[test]
fn a_trial_integration_evaluates_no_jacobian_per_substep() {
    let (m, x, u) = stiff_case();
    let m = Counting::new(m);
    let n = 16;
    let nx = m.nx();
    let mut counts = Vec::new();
    for simplified in [true, false] {
        let mut int = Integrator::new(&m, &settings(simplified, n), 0.25).unwrap();
        let mut xe = vec![0.0; nx];
        m.take();
        int.integrate(&m, &x, &u, &mut xe).unwrap();
        let trial = m.take();
        let mut a = DMatrix::zeros(nx, nx);
        let mut b = DMatrix::zeros(nx, m.nu());
        int.integrate_with_sensitivities(&m, &x, &u, &mut xe, &mut a, &mut b).unwrap();
        counts.push((trial, m.take()));
    }
    let ((trial_s, sens_s), (trial_f, sens_f)) = (counts[0], counts[1]);
    eprintln!("COUNTS trial {trial_s:?} sens {sens_s:?} full trial {trial_f:?} sens {sens_f:?}");
    assert_eq!(trial_s.1, 1, "simplified trial (rhs, jacobians) {trial_s:?}");
    // (a Jacobian predicted at the converged midpoint that is not there refreshes the factor:
    // a few more)
    assert!(
        (n + 1..=n + 1 + n / 4).contains(&sens_s.1),
        "simplified with sensitivities {sens_s:?}"
    );
    // full Newton: at least one Jacobian per substep for the iteration (+ n for the sensitivities)
    assert!(trial_f.1 >= n, "full Newton trial {trial_f:?}");
    assert!(sens_f.1 >= 2 * n, "full Newton with sensitivities {sens_f:?}");
    // linear convergence at rate ≤ 0.1 from the explicit guess: a few more residuals than
    // full Newton, bounded
    assert!(trial_s.0 <= 3 * trial_f.0, "rhs: simplified {trial_s:?}, full {trial_f:?}");
}

/// When the stale factor does not contract (a large state change between substeps), the
/// iteration refreshes its Jacobian and still converges to the full Newton midpoint.
#[test]
fn simplified_newton_refreshes_when_the_contraction_is_slow() {
    let (m, mut x, u) = stiff_case();
    // a fast spin with 4 substeps: full Newton needs 6–8 iterations per substep from the
    // explicit guess, and the factor of the previous substep is far off
    x[0] *= 4.0;
    x[1] *= 4.0;
    let m = Counting::new(m);
    let nx = m.nx();
    let mut ends = Vec::new();
    let mut jac = Vec::new();
    for simplified in [true, false] {
        let mut int = Integrator::new(&m, &settings(simplified, 4), 0.25).unwrap();
        let mut xe = vec![0.0; nx];
        m.take();
        int.integrate(&m, &x, &u, &mut xe).unwrap();
        jac.push(m.take().1);
        ends.push(xe);
    }
    let d = max_rel(&ends[1], &ends[0]);
    assert!(d < 1e-11, "{d:e}");
    assert!(jac[0] > 1, "simplified Newton never refreshed: {jac:?}");
    assert!(jac[0] <= jac[1], "more Jacobians than full Newton: {jac:?}");
}

/// `refresh_after_first_step`: the same end state and sensitivities to the Newton tolerance,
/// a Jacobian per substep in a trial (with the residual of its second iterate) and fewer
/// residual iterations than the contraction rule alone.
#[test]
fn refresh_after_the_first_step_trades_residuals_for_jacobians() {
    let (m, x, u) = stiff_case();
    let m = Counting::new(m);
    let n = 16;
    let (nx, nu) = (m.nx(), m.nu());
    let mut out = Vec::new();
    for refresh in [false, true] {
        let s = IntegratorSettings { refresh_after_first_step: refresh, ..settings(true, n) };
        let mut int = Integrator::new(&m, &s, 0.25).unwrap();
        let mut xe = vec![0.0; nx];
        m.take();
        int.integrate(&m, &x, &u, &mut xe).unwrap();
        let trial = m.take();
        let (mut xs, mut a, mut b) =
            (vec![0.0; nx], DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
        int.integrate_with_sensitivities(&m, &x, &u, &mut xs, &mut a, &mut b).unwrap();
        out.push((xe, trial, xs, a, b));
    }
    let (c, r) = (&out[0], &out[1]);
    assert!(max_rel(&c.0, &r.0) < 1e-11, "trial state {:e}", max_rel(&c.0, &r.0));
    assert!(max_rel(&c.2, &r.2) < 1e-11, "state {:e}", max_rel(&c.2, &r.2));
    assert!(max_rel(c.3.as_slice(), r.3.as_slice()) < 1e-9, "A");
    assert!(max_rel(c.4.as_slice(), r.4.as_slice()) < 1e-9, "B");
    // (rhs, jacobians): the counting model's `rhs_and_jacobians` counts one of each
    let ((rhs_c, jac_c), (rhs_r, jac_r)) = (c.1, r.1);
    assert_eq!(jac_c, 1, "contraction rule {:?}", c.1);
    assert!(jac_r >= n && jac_r <= 2 * n + 1, "after first step {:?}", r.1);
    // the residual iterations (right-hand sides not paired with a Jacobian) drop
    assert!(rhs_r - jac_r < rhs_c - jac_c, "contraction {:?}, after first step {:?}", c.1, r.1);
}
