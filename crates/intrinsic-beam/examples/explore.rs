//! Scratch exploration (to be replaced by a proper example).
use intrinsic_beam::samples::*;
use intrinsic_beam::*;
use std::time::Instant;

fn tip(sim: &ImplicitMidpoint) -> (f64, f64, f64) {
    let k = sim.kinematics();
    let n = k.r.len() - 1;
    let xi = k.xi[n];
    (k.r[n].x - 1.0, k.r[n].z, 2.0 * xi[0].abs().min(1.0).acos())
}

fn main() {
    let which = std::env::args().nth(1).unwrap_or_default();
    if which == "energy" {
        for comp in [Components::Planar, Components::Spatial] {
            let s = cantilever_release(comp, 20).unwrap();
            let mut sim =
                ImplicitMidpoint::new(s.problem, s.state, s.kinematics, NewtonSettings::default())
                    .unwrap();
            let e0 = sim.energy();
            let t = Instant::now();
            let mut maxd: f64 = 0.0;
            let mut maxtip: f64 = 0.0;
            for i in 0..10000 {
                sim.step(1e-3).unwrap();
                maxd = maxd.max((sim.energy() - e0).abs() / e0);
                maxtip = maxtip.max(tip(&sim).1.abs());
                if i % 2000 == 0 {
                    println!("{i} {:?} {:e}", tip(&sim), maxd);
                }
            }
            println!(
                "{comp:?} e0 {e0} drift {maxd:e} maxtip {maxtip} {:?} {:?}",
                t.elapsed(),
                sim.counters()
            );
        }
    }
    if which == "dead" {
        for n in [10, 20, 40] {
            let s = cantilever_dead_tip_load(Components::Planar, n).unwrap();
            let mut sim =
                ImplicitMidpoint::new(s.problem, s.state, s.kinematics, NewtonSettings::default())
                    .unwrap();
            let t = Instant::now();
            let dt = 0.01;
            for i in 0..1000 {
                sim.step(dt).unwrap();
                if i % 100 == 99 {
                    println!("{} {:?}", sim.time(), tip(&sim));
                }
            }
            println!("n={n} {:?} {:?} {:?}", tip(&sim), t.elapsed(), sim.counters());
        }
    }
    if which == "roll" {
        let s =
            cantilever_follower_moment(Components::Planar, 40, 2.0 * std::f64::consts::PI, 4, 3.0)
                .unwrap();
        let mut sim =
            ImplicitMidpoint::new(s.problem, s.state, s.kinematics, NewtonSettings::default())
                .unwrap();
        let dt = 0.01;
        let sched = roll_up_schedule(4, 3.0);
        let mut j = 0;
        while j < sched.len() {
            sim.step(dt).unwrap();
            if sim.time() >= sched[j] - 1e-9 {
                let th = 2.0 * std::f64::consts::PI * (j + 1) as f64 / 4.0;
                println!("theta {th} sim {:?} exact {:?}", tip(&sim), roll_up_tip(th));
                j += 1;
            }
        }
        println!("{:?}", sim.counters());
    }
}
