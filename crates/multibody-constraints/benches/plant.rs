//! Criterion benches of the constrained plant: the paper's two-links, 2×50 elements, 7.5 s of
//! motion at dt = 1e-3 after a rigid-rotation disturbance (goals: 2D < 0.5 s, 3D < 2 s on one
//! core), and single steps.
#![allow(missing_docs)] // criterion_group! generates an undocumented function
use criterion::{criterion_group, criterion_main, Criterion};
use intrinsic_beam::Section;
use multibody_constraints::{samples, Plant, PlantSettings, Structure};
use nalgebra::Vector3;

/// Tip position (node 50 of link 2) of a two-link after `t_end` at dt = 1e-3, released in a
/// rigid rotation `omega` about the root.
fn two_link_tip(
    structure: Structure,
    omega: Vector3<f64>,
    t_end: f64,
) -> multibody_constraints::Result<Vector3<f64>> {
    let dt = 1e-3;
    let x = structure.rigid_rotation_state(omega, Vector3::zeros());
    let mut plant = Plant::new(structure, PlantSettings { dt, ..Default::default() })?;
    plant.set_state(&x)?;
    for _ in 0..(t_end / dt).round() as usize {
        plant.step()?;
    }
    Ok(plant.position(1, 50))
}

fn full_runs(c: &mut Criterion) {
    let mut g = c.benchmark_group("plant-7.5s");
    g.sample_size(10);
    g.bench_function("2d-two-link-2x50-dt1e-3", |b| {
        b.iter(|| {
            two_link_tip(
                samples::paper_2d(Section::paper_2d(), 50, 0.0).expect("2d"),
                Vector3::y(),
                7.5,
            )
            .expect("run")
        })
    });
    g.bench_function("3d-two-link-2x50-dt1e-3", |b| {
        b.iter(|| {
            two_link_tip(
                samples::paper_3d(Section::paper_3d(), 50, 0.0).expect("3d"),
                Vector3::new(0.0, 1.0, 1.0),
                7.5,
            )
            .expect("run")
        })
    });
    g.finish();
}

fn single_steps(c: &mut Criterion) {
    let mut g = c.benchmark_group("plant-step");
    for (name, structure, omega) in [
        (
            "2d-two-link-2x50",
            samples::paper_2d(Section::paper_2d(), 50, 0.0).expect("2d"),
            Vector3::new(0.0, 1.0, 0.0),
        ),
        (
            "3d-two-link-2x50",
            samples::paper_3d(Section::paper_3d(), 50, 0.0).expect("3d"),
            Vector3::new(0.0, 1.0, 1.0),
        ),
    ] {
        let x = structure.rigid_rotation_state(omega, Vector3::zeros());
        let mut plant = Plant::new(structure, PlantSettings::default()).expect("plant");
        plant.set_state(&x).expect("state");
        g.bench_function(name, |b| b.iter(|| plant.step().expect("step")));
    }
    g.finish();
}

criterion_group!(benches, full_runs, single_steps);
criterion_main!(benches);
