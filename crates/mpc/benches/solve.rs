//! Per-sample solve time of the paper's NMPC (2D and 3D, paper mesh): one sample from the
//! initial rigid rotation (ω0 = 1), full SQP and real-time iteration, and one warm-started
//! sample after a shift. Timings are reported, never asserted (goal: worst < 50 ms, τs/4).
#![allow(missing_docs)] // criterion_group! generates an undocumented function
use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use mpc::{Controller, ControllerSettings, RomDynamics, Scenario, Setup};
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
                ControllerSettings { real_time_iteration: rti, ..ControllerSettings::default() };
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

criterion_group!(benches, bench);
criterion_main!(benches);
