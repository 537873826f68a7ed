//! Benchmarks of `intrinsic-beam`: one implicit-midpoint step of a 100-element cantilever
//! (planar and spatial; large-amplitude release and smooth swing; default settings, full
//! Newton, and the previous sparse-LU default), and a run-time-against-error
//! table for the clamped–free cantilever (printed before the criterion runs).
#![allow(missing_docs)] // criterion_group! generates an undocumented function

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use intrinsic_beam::closed_form::{bending, Supports};
use intrinsic_beam::samples::{self, Sample};
use intrinsic_beam::{family, linear_modes, Family};
use intrinsic_beam::{
    Beam, BeamProblem, Components, EndCondition, ImplicitMidpoint, LinearSolver, Loads, Mesh,
    NewtonSettings, StepRefresh,
};

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

/// Elements vs first bending frequency error (Euler–Bernoulli section, closed form), time of
/// the modal solve, and cost of implicit-midpoint steps of the same beam released from an arc
/// (minimum time per step over batches).
fn error_time_table() {
    let exact = bending(Supports::ClampedFree, 1.0, 1.0, 1.0, 1)[0];
    println!("\nrun time against error, clamped-free cantilever (planar, L = 1, EI = 1, m = 1)");
    println!(
        "| elements | ω1 rel. error | modal solve | step (μs) | Newton it./step | 1 s at dt=1e-3 |"
    );
    println!("|---:|---:|---:|---:|---:|---:|");
    for n in [10, 20, 50, 100, 200, 400] {
        let beam = Beam::new(
            samples::euler_bernoulli_section(),
            Mesh::uniform(1.0, n).unwrap(),
            Components::Planar,
        )
        .unwrap();
        let problem =
            BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())
                .unwrap();
        let t = Instant::now();
        let modes = linear_modes(&problem).unwrap();
        let modal = t.elapsed();
        let omega = modes
            .iter()
            .find(|m| m.omega > 1e-3 && family(&problem.beam, m) == Family::BendingE2)
            .unwrap()
            .omega;
        let mut sim = warmed(samples::cantilever_release(Components::Planar, n).unwrap(), 1e-3, 10);
        let before = sim.counters();
        // minimum over 10 batches of 20 steps: robust against preemption on a shared machine
        let (batches, per_batch) = (10, 20);
        let mut per_step = f64::INFINITY;
        for _ in 0..batches {
            let t = Instant::now();
            for _ in 0..per_batch {
                sim.step(1e-3).unwrap();
            }
            per_step = per_step.min(t.elapsed().as_secs_f64() / per_batch as f64);
        }
        let steps = batches * per_batch;
        let its =
            (sim.counters().newton_iterations - before.newton_iterations) as f64 / steps as f64;
        println!(
            "| {n} | {:.3e} | {:.1} ms | {:.0} | {:.1} | {:.2} s |",
            (omega - exact).abs() / exact,
            modal.as_secs_f64() * 1e3,
            per_step * 1e6,
            its,
            per_step * 1000.0
        );
    }
    println!();
}

fn step_benches(c: &mut Criterion) {
    error_time_table();
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
