//! Run time against error for the paper's two-links (docs/multibody.md): tip position at
//! 7.5 s for meshes and steps, against a fine reference. `cargo run --release --example
//! time_vs_error -- [2d|3d]`.
use multibody_constraints::studies::{paper_2d_tip, paper_3d_tip};

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "2d".into());
    let t_end = 7.5;
    let run = |n: usize, dt: f64| {
        if which == "3d" {
            paper_3d_tip(n, dt, t_end)
        } else {
            paper_2d_tip(n, dt, t_end)
        }
    };
    let (reference, rt) =
        if which == "3d" { run(80, 2.5e-4).unwrap() } else { run(100, 2.5e-4).unwrap() };
    eprintln!("reference {reference:?} in {rt:.1} s");
    println!("| elements per link | dt (s) | tip error at 7.5 s (m) | run time (s) |");
    println!("|---|---|---|---|");
    let cases: &[(usize, f64)] = if which == "3d" {
        &[(10, 2e-3), (20, 1e-3), (50, 1e-3), (50, 5e-4)]
    } else {
        &[(10, 2e-3), (20, 2e-3), (20, 1e-3), (50, 2e-3), (50, 1e-3), (50, 5e-4)]
    };
    for &(n, dt) in cases {
        let (tip, t) = run(n, dt).unwrap();
        println!("| {n} | {dt} | {:.2e} | {t:.2} |", (tip - reference).norm());
    }
}
