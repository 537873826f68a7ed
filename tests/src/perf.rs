//! The numerics of `cargo xtask bench` (docs/performance.md): the models, runs and error
//! measures of the studies (a) FE mesh against frequency error ([`mesh`]), (b) ROM mode count
//! against trajectory error ([`modes`]), (c) time step against error per integrator
//! ([`timestep`]) and (d) closed-loop cost against solve time per controller ([`control`]), and
//! the timing harness of every study ([`timed`]). xtask calls them, times them and turns the
//! numbers into tables and plots.

pub mod control;
pub mod mesh;
pub mod modes;
pub mod timestep;

use std::time::Instant;

/// The error of a study step: the library error (or message) that stopped it.
pub type Error = Box<dyn std::error::Error + Send + Sync>;

/// Result of a study step.
pub type Result<T> = std::result::Result<T, Error>;

/// Median wall time (s) per call of `f` over up to `k` timing samples, stopping early once
/// `budget` seconds are spent (at least one sample). Calls shorter than 20 ms are batched so
/// that each sample lasts about 20 ms (the clock and scheduler noise stay small against it).
/// Returns the last call's value with the median time per call.
pub fn timed<T, E>(
    k: usize,
    budget: f64,
    mut f: impl FnMut() -> std::result::Result<T, E>,
) -> std::result::Result<(T, f64), E> {
    const SAMPLE: f64 = 0.02;
    let start = Instant::now();
    let t = Instant::now();
    let mut last = f()?;
    let first = t.elapsed().as_secs_f64();
    let batch = if first < SAMPLE { (SAMPLE / first.max(1e-7)).ceil() as usize } else { 1 };
    let mut times = vec![first];
    while times.len() < k.max(1) && start.elapsed().as_secs_f64() < budget {
        let t = Instant::now();
        for _ in 0..batch {
            last = f()?;
        }
        times.push(t.elapsed().as_secs_f64() / batch as f64);
    }
    if times.len() > 1 {
        times.remove(0); // the first call warms caches and allocations
    }
    Ok((last, median(&mut times)))
}

/// Median of a non-empty slice (NaN for an empty one).
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Observed order of convergence between consecutive refinements: `log(e_i/e_{i+1}) /
/// log(h_i/h_{i+1})` (NaN where an error is not positive and finite).
pub fn orders(h: &[f64], e: &[f64]) -> Vec<f64> {
    let mut out = vec![f64::NAN];
    for i in 1..h.len() {
        let ok = |x: f64| x.is_finite() && x > 0.0;
        out.push(if ok(e[i]) && ok(e[i - 1]) {
            (e[i - 1] / e[i]).ln() / (h[i - 1] / h[i]).ln()
        } else {
            f64::NAN
        });
    }
    out
}
