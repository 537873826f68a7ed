//! Integrator sensitivities and second derivatives against central finite differences.

use nalgebra::DMatrix;
use ocp_transcription::samples::{self, CartPole, LinearModel, ModalLike};
use ocp_transcription::{Dynamics, Integrator, IntegratorKind, IntegratorSettings};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use rand::Rng;

const KINDS: [IntegratorKind; 3] =
    [IntegratorKind::Rk4, IntegratorKind::ImplicitMidpoint, IntegratorKind::LawsonRk4];

fn small_modal() -> ModalLike {
    ModalLike::new(8, 2, 20.0, 1.0, 3).unwrap()
}

/// Max relative deviation between analytic and central-difference sensitivities.
/// Central differences with step 1e-6 have truncation error ~ε²‖Φ'''‖ ≈ 1e-12 and
/// round-off ~1e-16/ε ≈ 1e-10, so 1e-6 (relative to 1 + |entry|) leaves a wide margin
/// while a wrong sensitivity (any missing term is O(h) ≈ 1e-2) fails.
fn fd_sensitivity_error<D: Dynamics>(model: &D, kind: IntegratorKind, x: &[f64], u: &[f64]) -> f64 {
    let settings = IntegratorSettings::new(kind, 3);
    let mut int = Integrator::new(model, &settings, 0.1).unwrap();
    fd_sensitivity_error_of(&mut int, model, x, u)
}

/// [`fd_sensitivity_error`] with a given integrator (its current substep count).
pub(crate) fn fd_sensitivity_error_of<D: Dynamics>(
    int: &mut Integrator,
    model: &D,
    x: &[f64],
    u: &[f64],
) -> f64 {
    samples::fd_sensitivity_error(int, model, x, u).unwrap()
}

/// Exact Hessian of λᵀΦ against central differences of the exact gradient Φ_zᵀλ.
fn fd_hessian_error<D: Dynamics>(
    model: &D,
    kind: IntegratorKind,
    x: &[f64],
    u: &[f64],
    lam: &[f64],
) -> f64 {
    let (nx, nu) = (model.nx(), model.nu());
    let nz = nx + nu;
    let settings = IntegratorSettings::new(kind, 3);
    let mut int = Integrator::new(model, &settings, 0.1).unwrap();
    int.enable_second_order().unwrap();
    let mut h = DMatrix::zeros(nz, nz);
    int.adjoint_hessian(model, x, u, lam, &mut h).unwrap();
    let grad = |int: &mut Integrator, x: &[f64], u: &[f64]| {
        let mut xe = vec![0.0; nx];
        let mut a = DMatrix::zeros(nx, nx);
        let mut b = DMatrix::zeros(nx, nu);
        int.integrate_with_sensitivities(model, x, u, &mut xe, &mut a, &mut b).unwrap();
        let mut g = vec![0.0; nz];
        for j in 0..nx {
            g[j] = (0..nx).map(|i| a[(i, j)] * lam[i]).sum();
        }
        for j in 0..nu {
            g[nx + j] = (0..nx).map(|i| b[(i, j)] * lam[i]).sum();
        }
        g
    };
    let eps = 1e-6;
    let mut err = 0.0_f64;
    for j in 0..nz {
        let (mut x1, mut u1, mut x2, mut u2) = (x.to_vec(), u.to_vec(), x.to_vec(), u.to_vec());
        if j < nx {
            x1[j] += eps;
            x2[j] -= eps;
        } else {
            u1[j - nx] += eps;
            u2[j - nx] -= eps;
        }
        let gp = grad(&mut int, &x1, &u1);
        let gm = grad(&mut int, &x2, &u2);
        for i in 0..nz {
            let fd = (gp[i] - gm[i]) / (2.0 * eps);
            err = err.max((fd - h[(i, j)]).abs() / (1.0 + h[(i, j)].abs()));
        }
    }
    err
}

fn config() -> Config {
    Config {
        cases: 64,
        rng_seed: RngSeed::Fixed(0x05ee_d0c9),
        failure_persistence: None,
        ..Config::default()
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn cartpole_sensitivities_match_finite_differences(
        x in prop::collection::vec(-2.0..2.0f64, 4), u in -20.0..20.0f64,
    ) {
        let model = CartPole::default();
        for kind in [IntegratorKind::Rk4, IntegratorKind::ImplicitMidpoint] {
            let e = fd_sensitivity_error(&model, kind, &x, &[u]);
            prop_assert!(e < 1e-6, "{kind:?}: {e}");
        }
    }

    #[test]
    fn modal_like_sensitivities_match_finite_differences(
        x in prop::collection::vec(-1.0..1.0f64, 8), u in prop::collection::vec(-1.0..1.0f64, 2),
    ) {
        let model = small_modal();
        for kind in KINDS {
            let e = fd_sensitivity_error(&model, kind, &x, &u);
            prop_assert!(e < 1e-6, "{kind:?}: {e}");
        }
    }

    #[test]
    fn exact_hessians_match_finite_differences(
        x in prop::collection::vec(-1.0..1.0f64, 8), u in prop::collection::vec(-1.0..1.0f64, 2),
        lam in prop::collection::vec(-1.0..1.0f64, 8),
    ) {
        let model = small_modal();
        for kind in [IntegratorKind::Rk4, IntegratorKind::LawsonRk4] {
            let e = fd_hessian_error(&model, kind, &x, &u, &lam);
            prop_assert!(e < 1e-6, "{kind:?}: {e}");
        }
        let cp = CartPole::default();
        let e = fd_hessian_error(&cp, IntegratorKind::Rk4, &x[..4], &u[..1], &lam[..4]);
        prop_assert!(e < 1e-6, "cart-pole: {e}");
    }
}

/// Lawson RK4 is exact on `ẋ = Ax + Bu` with `L = A` up to the quadrature of the constant
/// forcing; with `u = 0` it reproduces `e^{AΔt} x` to round-off.
#[test]
fn lawson_is_exact_on_the_linear_part() {
    let model = LinearModel::spring_chain(3, 1);
    let settings = IntegratorSettings::new(IntegratorKind::LawsonRk4, 2);
    let mut int = Integrator::new(&model, &settings, 0.7).unwrap();
    let x0 = [0.3, -0.2, 0.1, 0.5, 0.0, -0.4];
    let mut xe = [0.0; 6];
    int.integrate(&model, &x0, &[0.0], &mut xe).unwrap();
    let a = model.linear_part().unwrap();
    let exact = (a * 0.7).exp() * nalgebra::DVector::from_column_slice(&x0);
    for i in 0..6 {
        assert!((xe[i] - exact[i]).abs() < 1e-13, "{i}: {} vs {}", xe[i], exact[i]);
    }
}

/// Implicit midpoint keeps the quadratic invariant `½xᵀx` of the energy-conserving part
/// (`xᵀN(x)x = 0`, `W` skew without damping) to the Newton tolerance.
#[test]
fn implicit_midpoint_conserves_the_quadratic_invariant() {
    let model = ModalLike::new(9, 1, 30.0, 2.0, 11).unwrap();
    // the damping makes W non-skew: remove it by using the nonlinear part alone via L = 0 model
    let x0: Vec<f64> = (0..9).map(|i| 0.3 * ((i as f64) * 1.3).sin()).collect();
    assert!(model.nonlinear_power(&x0).abs() < 1e-14);
    struct Undamped(ModalLike);
    impl Dynamics for Undamped {
        fn nx(&self) -> usize {
            self.0.nx()
        }
        fn nu(&self) -> usize {
            self.0.nu()
        }
        fn rhs(&self, x: &[f64], u: &[f64], xdot: &mut [f64]) {
            self.0.rhs(x, u, xdot);
            let w = self.0.linear_part().unwrap();
            for i in 0..x.len() {
                xdot[i] -= w[(i, i)] * x[i];
            }
        }
        fn jacobians(&self, x: &[f64], u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
            self.0.jacobians(x, u, fx, fu);
            let w = self.0.linear_part().unwrap();
            for i in 0..x.len() {
                fx[(i, i)] -= w[(i, i)];
            }
        }
    }
    let m = Undamped(model);
    let mut int =
        Integrator::new(&m, &IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 5), 0.5)
            .unwrap();
    let mut x = x0.clone();
    let mut xe = vec![0.0; 9];
    let e0: f64 = x0.iter().map(|v| v * v).sum();
    for _ in 0..20 {
        int.integrate(&m, &x, &[0.0], &mut xe).unwrap();
        x.copy_from_slice(&xe);
    }
    let e1: f64 = x.iter().map(|v| v * v).sum();
    // 100 steps, each exact up to the Newton residual 1e-13 (relative)
    assert!((e1 - e0).abs() / e0 < 1e-10, "drift {}", (e1 - e0) / e0);
}

/// A NaN from the model is an error, not a NaN state.
#[test]
fn nan_dynamics_is_an_error() {
    struct Bad;
    impl Dynamics for Bad {
        fn nx(&self) -> usize {
            1
        }
        fn nu(&self) -> usize {
            1
        }
        fn rhs(&self, x: &[f64], _u: &[f64], xdot: &mut [f64]) {
            xdot[0] = if x[0] > 1.0 { f64::NAN } else { 1.0 };
        }
        fn jacobians(&self, _x: &[f64], _u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
            fx[(0, 0)] = 0.0;
            fu[(0, 0)] = 0.0;
        }
    }
    for kind in [IntegratorKind::Rk4, IntegratorKind::ImplicitMidpoint] {
        let mut int = Integrator::new(&Bad, &IntegratorSettings::new(kind, 4), 2.0).unwrap();
        let mut xe = [0.0];
        let r = int.integrate(&Bad, &[0.0], &[0.0], &mut xe);
        assert!(
            matches!(r, Err(ocp_transcription::OcpError::NonFiniteDynamics { .. })),
            "{kind:?}: {r:?}"
        );
    }
}

/// The ROM-structured sample: energy identity, the ROM's zero blocks in the Jacobian (so the
/// block-range product path runs: > 30 % nonzero, dense blocks cover < 90 %), and Lawson
/// sensitivities against central differences (tolerance as in `fd_sensitivity_error`).
#[test]
fn rom_like_model_has_the_rom_structure_and_exact_sensitivities() {
    let m = ModalLike::rom_like(24, 3, 60.0, 1.0, 5).unwrap();
    let n = m.nx();
    assert_eq!(n, 24);
    let mut rng = ocp_transcription::samples::seeded(9);
    let x: Vec<f64> = (0..n).map(|_| rng.random_range(-0.3..0.3)).collect();
    let u = [0.2, -0.4, 0.1];
    // xᵀN(x)x = 0: sums of ~100 products of size ≤ 30·0.3³, round-off ~1e-14
    assert!(m.nonlinear_power(&x).abs() < 1e-12, "{}", m.nonlinear_power(&x));
    let (mut fx, mut fu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, 3));
    m.jacobians(&x, &u, &mut fx, &mut fu);
    let w = m.linear_part().unwrap();
    let nl = &fx - &w;
    let nnz = nl.iter().filter(|v| **v != 0.0).count();
    assert!(nnz * 10 > 3 * n * n, "nonlinear Jacobian too sparse: {nnz}");
    // x = [q1 (m = 10), q2 (6), qξ (8)]: zero blocks (q1, q2) × qξ and qξ × q2
    for i in 0..n {
        for j in 0..n {
            if (i < 16 && j >= 16) || (i >= 16 && (10..16).contains(&j)) {
                assert_eq!(nl[(i, j)], 0.0, "({i}, {j})");
            }
        }
    }
    let err = fd_sensitivity_error(&m, IntegratorKind::LawsonRk4, &x, &u);
    assert!(err < 1e-6, "{err}");
}

/// `rhs_and_jacobians`: the default (rhs + jacobians) and the ROM-like sample's override by
/// Euler's identity `f = ½(∂f/∂x + W)x + Bu` give the same values (round-off: sums of ~100
/// terms of size ≤ 1, so 1e-12 relative).
#[test]
fn rhs_and_jacobians_agree_with_separate_calls() {
    let m = ModalLike::rom_like(30, 4, 80.0, 0.5, 2).unwrap();
    let c = CartPole::default();
    let mut rng = ocp_transcription::samples::seeded(4);
    let x: Vec<f64> = (0..30).map(|_| rng.random_range(-1.0..1.0)).collect();
    let u = [0.3, -0.2, 0.9, -1.0];
    let check = |d: &dyn Dynamics, x: &[f64], u: &[f64]| {
        let (n, nu) = (d.nx(), d.nu());
        let (mut f1, mut f2) = (vec![0.0; n], vec![0.0; n]);
        let (mut a1, mut b1) = (DMatrix::zeros(n, n), DMatrix::zeros(n, nu));
        let (mut a2, mut b2) = (DMatrix::zeros(n, n), DMatrix::zeros(n, nu));
        d.rhs(x, u, &mut f1);
        d.jacobians(x, u, &mut a1, &mut b1);
        d.rhs_and_jacobians(x, u, &mut f2, &mut a2, &mut b2);
        let scale = f1.iter().fold(1.0_f64, |s, v| s.max(v.abs()));
        for i in 0..n {
            assert!((f1[i] - f2[i]).abs() <= 1e-12 * scale, "row {i}: {} vs {}", f1[i], f2[i]);
        }
        assert_eq!(a1, a2);
        assert_eq!(b1, b2);
    };
    check(&m, &x, &u);
    check(&c, &[0.1, 0.5, -0.3, 0.2], &[2.0]);
}

/// A Lawson trial without sensitivities uses the model's `remainder` (`f − Lx` without the
/// products with `L`): it agrees with `rhs − Lx` and with the state of the pass with
/// sensitivities to round-off (‖x‖ ≈ 1, tolerance 1e-12 relative; a missing term is O(1)).
#[test]
fn lawson_trial_with_the_model_remainder_matches_the_sensitivity_pass() {
    use ocp_transcription::samples::{seeded, ModalLike};
    let m = ModalLike::rom_like(61, 5, 175.0, 0.1, 7).unwrap();
    let (nx, nu) = (m.nx(), m.nu());
    let w = m.linear_part().unwrap();
    let mut rng = seeded(5);
    let mut int =
        Integrator::new(&m, &IntegratorSettings::new(IntegratorKind::LawsonRk4, 16), 0.25).unwrap();
    for _ in 0..4 {
        let x: Vec<f64> = (0..nx).map(|_| rng.random_range(-1.0..1.0)).collect();
        let u: Vec<f64> = (0..nu).map(|_| rng.random_range(-1.0..1.0)).collect();
        let (mut g, mut f) = (vec![f64::NAN; nx], vec![0.0; nx]);
        assert!(m.remainder(&x, &u, &mut g));
        m.rhs(&x, &u, &mut f);
        let wx = &w * nalgebra::DVector::from_column_slice(&x);
        let scale = f.iter().fold(1.0_f64, |a, v| a.max(v.abs()));
        for i in 0..nx {
            assert!((g[i] - (f[i] - wx[i])).abs() <= 1e-12 * scale, "{i}");
        }
        let (mut x1, mut x2) = (vec![0.0; nx], vec![0.0; nx]);
        int.integrate(&m, &x, &u, &mut x1).unwrap();
        let (mut a, mut b) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
        int.integrate_with_sensitivities(&m, &x, &u, &mut x2, &mut a, &mut b).unwrap();
        let n = x2.iter().fold(1.0_f64, |a, v| a.max(v.abs()));
        for i in 0..nx {
            assert!((x1[i] - x2[i]).abs() <= 1e-12 * n, "{i}: {} vs {}", x1[i], x2[i]);
        }
    }
}
