//! Runs the paper's two-link (2×N elements, 7.5 s at dt = 1e-3) for profiling:
//! `cargo run --release --example profile_2d -- [N] [2d|3d]`.
use multibody_constraints::studies::{paper_2d_tip, paper_3d_tip};

fn main() {
    let n: usize = std::env::args().nth(1).map(|s| s.parse().expect("N")).unwrap_or(50);
    let three = std::env::args().nth(2).as_deref() == Some("3d");
    let (tip, seconds) =
        if three { paper_3d_tip(n, 1e-3, 7.5) } else { paper_2d_tip(n, 1e-3, 7.5) }.expect("run");
    println!("{} 2x{n}: {seconds:.3} s, tip {tip:?}", if three { "3D" } else { "2D" });
}
