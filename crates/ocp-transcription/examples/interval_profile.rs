//! One shooting interval with sensitivities on the ROM-structured sample, in a loop, for
//! profilers (`valgrind --tool=callgrind`, `perf stat`): `interval_profile [substeps] [calls]
//! [omega0]` at the rotating state of `omega0` (default 2) with random inputs in [−1, 1].
//! Prints the nonlinear Jacobian's max row sum at the state and the wall time per interval.

use nalgebra::DMatrix;
use ocp_transcription::samples::{ModalLike, SplitMix64};
use ocp_transcription::{Dynamics, Integrator, IntegratorKind, IntegratorSettings};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize, d: f64| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let substeps = arg(1, 20.0) as usize;
    let calls = arg(2, 200.0) as usize;
    let omega0 = arg(3, 2.0);
    let m = ModalLike::paper_sized_rom();
    let (nx, nu) = (m.nx(), m.nu());
    let mut rng = SplitMix64::new(2024);
    let x = m.rotating_state(omega0).expect("rom-like");
    let u: Vec<f64> = (0..nu).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let (mut fx, mut fu) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
    m.jacobians(&x, &u, &mut fx, &mut fu);
    let jg = fx - m.linear_part().expect("modal");
    let row_sum = jg.row_iter().map(|r| r.iter().map(|v| v.abs()).sum::<f64>()).fold(0.0, f64::max);
    let settings = IntegratorSettings::new(IntegratorKind::LawsonRk4, substeps);
    let mut int = Integrator::new(&m, &settings, 0.25).expect("valid");
    let mut xe = vec![0.0; nx];
    let (mut a, mut b) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
    let t = Instant::now();
    for _ in 0..calls {
        int.integrate_with_sensitivities(&m, &x, &u, &mut xe, &mut a, &mut b).expect("finite");
    }
    println!(
        "nx {nx}, {} tensor entries, ω0 = {omega0}: max row sum of ∂(N(x)x)/∂x {row_sum:.1}; Lawson × {substeps}: {:.1} µs per interval (wall)",
        m.tensor_entries(),
        t.elapsed().as_secs_f64() * 1e6 / calls as f64
    );
}
