//! Newton iterations, factorisations and time per implicit-midpoint step of the 100-element
//! bench cantilevers (planar and spatial, release and swing), for given Newton settings:
//! `cargo run --release -p intrinsic-beam --example step_cost -- [tolerance] [contraction_limit]
//! [extrapolate 0/1] [reuse 0/1]`.

use std::time::Instant;

use intrinsic_beam::samples::{self, Sample};
use intrinsic_beam::{Components, ImplicitMidpoint, NewtonSettings};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let d = NewtonSettings::default();
    let arg = |i: usize| args.get(i).map(|s| s.parse::<f64>().expect("number"));
    let settings = NewtonSettings {
        tolerance: arg(0).unwrap_or(d.tolerance),
        contraction_limit: arg(1).unwrap_or(d.contraction_limit),
        extrapolate: arg(2).map_or(d.extrapolate, |v| v != 0.0),
        reuse_jacobian: arg(3).map_or(d.reuse_jacobian, |v| v != 0.0),
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
            let s = make(comp, 100).expect("sample");
            let mut sim =
                ImplicitMidpoint::new(s.problem, s.state, s.kinematics, settings).expect("valid");
            for _ in 0..50 {
                sim.step(1e-3).expect("step");
            }
            let c0 = sim.counters();
            let steps = 400;
            let t = Instant::now();
            for _ in 0..steps {
                sim.step(1e-3).expect("step");
            }
            let us = t.elapsed().as_secs_f64() / steps as f64 * 1e6;
            let c1 = sim.counters();
            let its = (c1.newton_iterations - c0.newton_iterations) as f64 / steps as f64;
            let fac = (c1.factorizations - c0.factorizations) as f64 / steps as f64;
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
