//! Benchmarks of `intrinsic-beam`: one implicit-midpoint step of a 100-element cantilever
//! (planar and spatial; large-amplitude release and smooth swing; default settings, full
//! Newton, and the previous sparse-LU default). Run time against error is `cargo xtask bench`
//! (docs/performance.md).
#![allow(missing_docs)] // criterion_group! generates an undocumented function

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use intrinsic_beam::samples::{self, Sample};
use intrinsic_beam::{Components, ImplicitMidpoint, LinearSolver, NewtonSettings, StepRefresh};

fn warmed(sample: Sample, dt: f64, steps: usize) -> ImplicitMidpoint {
    warmed_with(sample, dt, steps, NewtonSettings::default())
}

fn warmed_with(
    sample: Sample,
    dt: f64,
    steps: usize,
    settings: NewtonSettings,
) -> ImplicitMidpoint {
    let mut sim = ImplicitMidpoint::new(sample.problem, sample.state, sample.kinematics, settings)
        .expect("valid sample");
    for _ in 0..steps {
        sim.step(dt).expect("step converges");
    }
    sim
}

fn step_benches(c: &mut Criterion) {
    let mut group = c.benchmark_group("implicit_midpoint_step_100_elements");
    group.warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(4));
    // previous default: faer sparse LU, factorisation refreshed only on slow contraction
    let sparse = NewtonSettings {
        linear_solver: LinearSolver::SparseLu,
        step_refresh: StepRefresh::Never,
        ..NewtonSettings::default()
    };
    // full Newton: a fresh Jacobian and factorisation every iteration
    let full = NewtonSettings { reuse_jacobian: false, ..NewtonSettings::default() };
    for (name, comp) in [("planar", Components::Planar), ("spatial", Components::Spatial)] {
        let mut sim = warmed(samples::cantilever_release(comp, 100).unwrap(), 1e-3, 50);
        group.bench_function(format!("{name}/release"), |b| {
            b.iter(|| black_box(sim.step(1e-3).unwrap()))
        });
        let mut sim = warmed(samples::cantilever_swing(comp, 100).unwrap(), 1e-3, 50);
        group.bench_function(format!("{name}/swing"), |b| {
            b.iter(|| black_box(sim.step(1e-3).unwrap()))
        });
        let mut sim = warmed_with(samples::cantilever_release(comp, 100).unwrap(), 1e-3, 50, full);
        group.bench_function(format!("{name}/release-full-newton"), |b| {
            b.iter(|| black_box(sim.step(1e-3).unwrap()))
        });
        let mut sim =
            warmed_with(samples::cantilever_release(comp, 100).unwrap(), 1e-3, 50, sparse);
        group.bench_function(format!("{name}/release-sparse-lu"), |b| {
            b.iter(|| black_box(sim.step(1e-3).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, step_benches);
criterion_main!(benches);
