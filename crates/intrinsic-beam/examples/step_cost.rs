//! Newton iterations, factorisations and time per implicit-midpoint step (minimum over 40 batches of 20 steps, and on-CPU time per
//! step from `/proc/thread-self/schedstat`) of the 100-element
//! bench cantilevers (planar and spatial, release and swing), for given Newton settings:
//! `cargo run --release -p intrinsic-beam --example step_cost -- [tolerance] [contraction_limit]
//! [extrapolate 0/1] [reuse 0/1] [sparse LU 0/1] [3/6: one component set only, 0 both]
//! [step refresh 0 never/1 always/2 auto]`.

use std::time::Instant;

use intrinsic_beam::samples::{self, Sample};
use intrinsic_beam::{
    Components, ImplicitMidpoint, LinearSolver, NewtonSettings, StepInput, StepRefresh,
};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let d = NewtonSettings::default();
    let arg = |i: usize| args.get(i).map(|s| s.parse::<f64>().expect("number"));
    let settings = NewtonSettings {
        tolerance: arg(0).unwrap_or(d.tolerance),
        contraction_limit: arg(1).unwrap_or(d.contraction_limit),
        extrapolate: arg(2).map_or(d.extrapolate, |v| v != 0.0),
        reuse_jacobian: arg(3).map_or(d.reuse_jacobian, |v| v != 0.0),
        step_refresh: match arg(6).map(|v| v as i64) {
            Some(0) => StepRefresh::Never,
            Some(1) => StepRefresh::Always,
            _ => d.step_refresh,
        },
        linear_solver: match arg(4) {
            Some(v) if v != 0.0 => LinearSolver::SparseLu,
            _ => d.linear_solver,
        },
        ..d
    };
    println!("{settings:?}");
    println!("| case | it./step | fact./step | µs/step planar | µs/step spatial | ratio |");
    type Make = fn(Components, usize) -> intrinsic_beam::Result<Sample>;
    let cases: [(&str, Make); 2] =
        [("release", samples::cantilever_release), ("swing", samples::cantilever_swing)];
    for (name, make) in cases {
        let mut row = Vec::new();
        for comp in [Components::Planar, Components::Spatial] {
            // optional 6th argument: 3 = planar only, 6 = spatial only (profiling)
            if arg(5).is_some_and(|k| k != 0.0 && k as usize != comp.k()) {
                row.push((0.0, 0.0, f64::NAN));
                continue;
            }
            let s = make(comp, 100).expect("sample");
            let mut sim =
                ImplicitMidpoint::new(s.problem, s.state, s.kinematics, settings).expect("valid");
            for _ in 0..50 {
                sim.step(1e-3).expect("step");
            }
            let c0 = sim.counters();
            let cpu0 = thread_cpu_ns();
            // minimum over batches of 20 steps: robust against preemption on a loaded machine
            let (batches, per_batch) = (40, 20);
            let mut us = f64::INFINITY;
            for _ in 0..batches {
                let t = Instant::now();
                for _ in 0..per_batch {
                    sim.step(1e-3).expect("step");
                }
                us = us.min(t.elapsed().as_secs_f64() / per_batch as f64 * 1e6);
            }
            let steps = batches * per_batch;
            // CPU time of this thread per step (excludes time preempted by other processes)
            let cpu_us =
                thread_cpu_ns().zip(cpu0).map(|(b, a)| (b - a) as f64 / steps as f64 / 1e3);
            let c1 = sim.counters();
            let its = (c1.newton_iterations - c0.newton_iterations) as f64 / steps as f64;
            let fac = (c1.factorizations - c0.factorizations) as f64 / steps as f64;
            // the step residual alone, at the converged state (one Newton iteration's share)
            let beam = &sim.problem().beam;
            let mut res = vec![0.0; beam.n_rows()];
            let input = StepInput {
                time: sim.time(),
                dt: 1e-3,
                loads: &sim.problem().loads,
                node_quaternions: &sim.kinematics().xi,
            };
            let mut res_us = f64::INFINITY;
            for _ in 0..40 {
                let t = Instant::now();
                for _ in 0..50 {
                    beam.step_residual(&input, sim.state(), sim.state(), &mut res)
                        .expect("residual");
                }
                res_us = res_us.min(t.elapsed().as_secs_f64() / 50.0 * 1e6);
            }
            println!(
                "  {name} {comp:?}: {} ({} fallbacks), residual {res_us:.1} µs, CPU time {} µs/step",
                sim.linear_solver_name(),
                c1.sparse_fallbacks,
                cpu_us.map_or("n/a".to_string(), |v| format!("{v:.0}"))
            );
            row.push((its, fac, us));
        }
        println!(
            "| {name} | {:.2} / {:.2} | {:.3} / {:.3} | {:.0} | {:.0} | {:.2} |",
            row[0].0,
            row[1].0,
            row[0].1,
            row[1].1,
            row[0].2,
            row[1].2,
            row[1].2 / row[0].2
        );
    }
}

/// On-CPU time of the calling thread in ns (`/proc/thread-self/schedstat`, Linux), if available.
fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}
