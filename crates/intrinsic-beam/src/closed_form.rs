//! Closed-form angular frequencies of uniform beams (the first `count` non-zero ones):
//! axial and torsional waves, Euler–Bernoulli bending by bisection on the characteristic
//! equations — the references of the frequency convergence checks.

use std::f64::consts::PI;

/// Support kinds for closed-form references.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Supports {
    /// Clamped at s = 0, free at s = L.
    ClampedFree,
    /// Pinned (translations fixed, rotations free) at s = 0, free at s = L.
    PinnedFree,
    /// Free at both ends.
    FreeFree,
}

/// Axial (wave speed `c`) or torsional: fixed–free `(2j−1)πc/2L`, free–free `jπc/L`.
pub fn wave(supports: Supports, fixed: bool, c: f64, length: f64, count: usize) -> Vec<f64> {
    (1..=count)
        .map(|j| {
            let j = j as f64;
            if fixed && supports != Supports::FreeFree {
                (2.0 * j - 1.0) * PI * c / (2.0 * length)
            } else {
                j * PI * c / length
            }
        })
        .collect()
}

/// Euler–Bernoulli bending `ω_j = (β_j L)² √(EI/(m L⁴))`, with `β_j L` the roots of
/// `cos β cosh β + 1 = 0` (clamped–free), `tan β − tanh β = 0` (pinned–free, non-zero),
/// `cos β cosh β − 1 = 0` (free–free, non-zero), found by bisection.
///
/// ```
/// use intrinsic_beam::closed_form::{bending, Supports};
///
/// // clamped–free: (β1 L)² with β1 L = 1.8751
/// let w = bending(Supports::ClampedFree, 1.0, 1.0, 1.0, 2);
/// assert!((w[0] - 1.875104068711961f64.powi(2)).abs() < 1e-12);
/// ```
pub fn bending(supports: Supports, ei: f64, m: f64, length: f64, count: usize) -> Vec<f64> {
    let f = |b: f64| match supports {
        Supports::ClampedFree => b.cos() * b.cosh() + 1.0,
        // tan β = tanh β  ⇔  sin β cosh β − cos β sinh β = 0 (scaled by e^{−β})
        Supports::PinnedFree => (b.sin() * b.cosh() - b.cos() * b.sinh()) * (-b).exp(),
        Supports::FreeFree => (b.cos() * b.cosh() - 1.0) * (-b).exp(),
    };
    let f_scaled = |b: f64| match supports {
        Supports::ClampedFree => f(b) * (-b).exp(),
        _ => f(b),
    };
    let mut roots = Vec::new();
    // roots lie in ((j − ½)π, (j + ½)π) bracket scans on a fine grid
    let mut a = 0.5;
    let step = 0.01;
    while roots.len() < count {
        let b = a + step;
        let (fa, fb) = (f_scaled(a), f_scaled(b));
        if fa == 0.0 || fa * fb < 0.0 {
            let (mut lo, mut hi) = (a, b);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if f_scaled(lo) * f_scaled(mid) <= 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            roots.push(0.5 * (lo + hi));
        }
        a = b;
    }
    roots.iter().map(|b| b * b * (ei / (m * length.powi(4))).sqrt()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bending_roots_match_tables() {
        let cf = bending(Supports::ClampedFree, 1.0, 1.0, 1.0, 2);
        assert!((cf[0] - 1.875104068711961f64.powi(2)).abs() < 1e-12);
        assert!((cf[1] - 4.694091132974175f64.powi(2)).abs() < 1e-11);
        let pf = bending(Supports::PinnedFree, 1.0, 1.0, 1.0, 1);
        assert!((pf[0] - 3.926602312047919f64.powi(2)).abs() < 1e-11);
        let ff = bending(Supports::FreeFree, 1.0, 1.0, 1.0, 1);
        assert!((ff[0] - 4.730040744862704f64.powi(2)).abs() < 1e-11);
    }
}
