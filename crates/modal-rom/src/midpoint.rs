//! The implicit midpoint rule `x⁺ = x + dt f((x + x⁺)/2, u)` on a modal model, solved by Newton
//! on the model's exact Jacobian (faer LU): the one step routine of [`crate::ModalRom`] and
//! [`crate::ExactJointsRom`]. The rule keeps every quadratic invariant of the model (theory.md
//! §2, §5, §10).

use crate::error::{ModalError, Result};
use faer::linalg::solvers::Solve;
use faer::Mat;

/// Newton on `z − x − dt f((x + z)/2) = 0` from `z = x`, to `‖Δz‖∞ ≤ tol · max(1, ‖x‖∞)`.
/// `rhs_and_jacobian(mid, f, jx)` writes `f(mid)` and its column-major `n × n` Jacobian.
/// Writes `x⁺` into `x` and returns the Newton iterations; `stage` names the model in errors.
pub(crate) fn newton_step(
    x: &mut [f64],
    dt: f64,
    tol: f64,
    max_iter: usize,
    stage: &str,
    mut rhs_and_jacobian: impl FnMut(&[f64], &mut [f64], &mut [f64]) -> Result<()>,
) -> Result<usize> {
    let n = x.len();
    let x0 = x.to_vec();
    let mut z = x0.clone();
    let mut mid = vec![0.0; n];
    let mut f = vec![0.0; n];
    let mut jx = vec![0.0; n * n];
    let scale = x0.iter().fold(1.0f64, |a, v| a.max(v.abs()));
    for it in 1..=max_iter {
        for i in 0..n {
            mid[i] = 0.5 * (x0[i] + z[i]);
        }
        rhs_and_jacobian(&mid, &mut f, &mut jx)?;
        let mut a = Mat::<f64>::from_fn(n, n, |i, j| -0.5 * dt * jx[j * n + i]);
        for i in 0..n {
            a[(i, i)] += 1.0;
        }
        let mut r = Mat::<f64>::from_fn(n, 1, |i, _| -(z[i] - x0[i] - dt * f[i]));
        a.partial_piv_lu().solve_in_place(r.as_mut());
        let mut step = 0.0f64;
        for i in 0..n {
            z[i] += r[(i, 0)];
            step = step.max(r[(i, 0)].abs());
        }
        if !step.is_finite() {
            return Err(ModalError::Numerical {
                stage: stage.into(),
                reason: "non-finite update".into(),
            });
        }
        if step <= tol * scale {
            x.copy_from_slice(&z);
            return Ok(it);
        }
    }
    Err(ModalError::Numerical {
        stage: stage.into(),
        reason: format!("no convergence in {max_iter} iterations"),
    })
}
