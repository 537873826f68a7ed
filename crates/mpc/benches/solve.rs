//! Per-sample solve time of the paper's NMPC (2D and 3D, paper mesh): one sample from the
//! initial rigid rotation (ω0 = 1), full SQP and real-time iteration, and one warm-started
//! sample after a shift; and one shooting interval with sensitivities on the real 3D ROM
//! (`rom-interval-3d`, Lawson RK4, Δt = 0.25 s, the model's integration cost in isolation).
//! Timings are reported, never asserted (goal: worst < 50 ms, τs/4).
//! Filter: `cargo bench -p mpc --bench solve -- rom-interval`.
#![allow(missing_docs)] // criterion_group! generates an undocumented function
use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use mpc::{Controller, ControllerSettings, RomDynamics, Scenario, Setup};
use nalgebra::DMatrix;
use ocp_transcription::{Dynamics, Integrator, IntegratorKind, IntegratorSettings};
use std::time::Duration;

fn initial_state(setup: &Setup, omega0: f64) -> Vec<f64> {
    let s = &setup.scenario;
    let w = nalgebra::Vector3::from_column_slice(&s.omega_direction) * omega0;
    let x0 = s.structure.rigid_rotation_state(w, nalgebra::Vector3::zeros());
    setup.rom.project_full(&x0, None).expect("projection")
}

fn controller(setup: &Setup, settings: &ControllerSettings) -> Controller {
    Controller::new(
        RomDynamics::new(&setup.rom).expect("model"),
        &setup.weights,
        &setup.scenario.mpc,
        settings,
    )
    .expect("controller")
}

/// One Lawson interval with `A`, `B` on the paper's 3D ROM (50 elements per link) at the
/// rotating initial state of ω0 = 1 and 2 with inputs (0.5, −0.5, …).
fn rom_interval(c: &mut Criterion) {
    let setup = Setup::new(&Scenario::paper_3d(50).expect("scenario")).expect("setup");
    let d = RomDynamics::new(&setup.rom).expect("model");
    let (nx, nu) = (d.nx(), d.nu());
    let u: Vec<f64> = (0..nu).map(|i| if i % 2 == 0 { 0.5 } else { -0.5 }).collect();
    let mut g = c.benchmark_group("rom-interval-3d");
    g.sample_size(30);
    for omega0 in [1.0, 2.0] {
        let q = initial_state(&setup, omega0);
        for n in [16, 20] {
            let settings = IntegratorSettings::new(IntegratorKind::LawsonRk4, n);
            let mut int = Integrator::new(&d, &settings, 0.25).expect("integrator");
            let mut xe = vec![0.0; nx];
            let (mut a, mut b) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
            g.bench_function(format!("nx{nx}_w{omega0}_lawson{n}"), |bch| {
                bch.iter(|| int.integrate_with_sensitivities(&d, &q, &u, &mut xe, &mut a, &mut b))
            });
        }
    }
    g.finish();
}

fn bench(c: &mut Criterion) {
    for (name, scenario) in [
        ("2d", Scenario::paper_2d(50).expect("scenario")),
        ("3d", Scenario::paper_3d(50).expect("scenario")),
    ] {
        let setup = Setup::new(&scenario).expect("setup");
        let q = initial_state(&setup, 1.0);
        let mut g = c.benchmark_group(format!("nmpc-{name}"));
        g.sample_size(10).measurement_time(Duration::from_secs(if name == "3d" { 60 } else { 10 }));
        for (label, rti) in [("sqp", false), ("rti", true)] {
            let settings =
                ControllerSettings { real_time_iteration: rti, ..ControllerSettings::full_sqp() };
            // a warm sample: the controller has solved the first sample; time the second
            g.bench_function(format!("{label}-warm-sample"), |b| {
                b.iter_batched(
                    || {
                        let mut c = controller(&setup, &settings);
                        c.step(0.0, &q).expect("first sample");
                        c
                    },
                    |mut c| c.step(0.2, &q).expect("sample"),
                    BatchSize::LargeInput,
                )
            });
        }
        g.finish();
    }
}

criterion_group!(benches, rom_interval, bench);
criterion_main!(benches);
