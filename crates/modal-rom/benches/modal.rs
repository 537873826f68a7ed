//! Criterion benches: RHS + Jacobian of the 3D augmented model (4 rigid + 16 elastic modes),
//! and the constrained modes of the 3D two-link at 2×50 elements.

#![allow(missing_docs)] // criterion's macros generate undocumented items

use criterion::{criterion_group, criterion_main, Criterion};
use modal_rom::samples::{self, paper_3d_selection};
use modal_rom::{BasisSettings, ModeSelection, RomOptions, StructureModel};
use std::hint::black_box;
use std::time::Instant;

/// Prints CPU and wall time per call of `f` over `calls` calls (criterion's figures are wall
/// times, inflated when other jobs share the cores; CPU time is not).
fn cpu_report(label: &str, calls: usize, clock: fn() -> Option<f64>, mut f: impl FnMut()) {
    let (Some(c0), w0) = (clock(), Instant::now()) else { return };
    for _ in 0..calls {
        f();
    }
    let (Some(c1), w1) = (clock(), w0.elapsed().as_secs_f64()) else { return };
    eprintln!(
        "{label}: CPU {:.3e} s/call, wall {:.3e} s/call over {calls} calls",
        (c1 - c0) / calls as f64,
        w1 / calls as f64
    );
}

fn rhs_jacobian(c: &mut Criterion) {
    let s = samples::paper_3d(20, 0.0, true, &paper_3d_selection(), &RomOptions::default())
        .expect("paper 3D sample");
    let rom = s.rom;
    let n = rom.n_state();
    let q: Vec<f64> = (0..n).map(|i| 0.1 * (i as f64 * 0.37).sin()).collect();
    let u = vec![0.3; rom.n_inputs()];
    let mut f = vec![0.0; n];
    let mut jq = vec![0.0; n * n];
    let mut ju = vec![0.0; n * rom.n_inputs()];
    eprintln!(
        "3D augmented model: {} modes, state {n}, Γ1 fill {:.3}, Γ2 fill {:.3}, Γξ fill {:.3}",
        rom.n_modes(),
        rom.gamma1().fill(),
        rom.gamma2().fill(),
        rom.quaternion().map_or(0.0, |q| q.gamma_xi_scaled.fill())
    );
    cpu_report(
        "rom3d_rhs_and_jacobian_fused (thread CPU)",
        20_000,
        ocp_transcription::thread_cpu_time,
        || {
            rom.rhs_and_jacobian(black_box(&q), black_box(&u), &mut f, &mut jq, &mut ju)
                .expect("rhs and jacobian")
        },
    );
    c.bench_function("rom3d_rhs_and_jacobian_fused", |b| {
        b.iter(|| {
            rom.rhs_and_jacobian(black_box(&q), black_box(&u), &mut f, &mut jq, &mut ju)
                .expect("rhs and jacobian")
        })
    });
    c.bench_function("rom3d_rhs_plus_jacobian", |b| {
        b.iter(|| {
            rom.rhs(black_box(&q), black_box(&u), &mut f).expect("rhs");
            rom.jacobian(black_box(&q), black_box(&u), &mut jq, &mut ju).expect("jac");
        })
    });
}

fn modes(c: &mut Criterion) {
    let structure =
        multibody_constraints::samples::paper_3d(intrinsic_beam::Section::paper_3d(), 50, 0.0)
            .expect("paper 3D structure");
    let model = StructureModel::new(&structure).expect("model");
    cpu_report(
        "modes3d_2x50 constrained_modes_first20 (process CPU)",
        20,
        ocp_transcription::process_cpu_time,
        || {
            let basis = model.modes(&BasisSettings::default()).expect("modes");
            black_box(basis.select(&ModeSelection::Lowest(20)).expect("select"));
        },
    );
    let mut group = c.benchmark_group("modes3d_2x50");
    group.sample_size(10);
    group.bench_function("constrained_modes_first20", |b| {
        b.iter(|| {
            let basis = model.modes(&BasisSettings::default()).expect("modes");
            black_box(basis.select(&ModeSelection::Lowest(20)).expect("select"))
        })
    });
    group.bench_function("structure_to_modes_first20", |b| {
        b.iter(|| {
            let model = StructureModel::new(&structure).expect("model");
            let basis = model.modes(&BasisSettings::default()).expect("modes");
            black_box(basis.select(&ModeSelection::Lowest(20)).expect("select"))
        })
    });
    group.finish();
}

criterion_group!(benches, rhs_jacobian, modes);
criterion_main!(benches);
