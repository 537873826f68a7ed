//! Runs the paper's 2D two-link (2×50 elements, 7.5 s at dt = 1e-3) for profiling.
use intrinsic_beam::Section;
use multibody_constraints::{samples, Plant, PlantSettings};
use nalgebra::Vector3;

fn main() {
    let n: usize = std::env::args().nth(1).map(|s| s.parse().unwrap()).unwrap_or(50);
    let structure = samples::paper_2d(Section::paper_2d(), n, 0.0).unwrap();
    let mut plant = Plant::new(structure, PlantSettings::default()).unwrap();
    let x = plant.structure().rigid_rotation_state(Vector3::new(0.0, 1.0, 0.0), Vector3::zeros());
    plant.set_state(&x).unwrap();
    let t = std::time::Instant::now();
    let (mut iters, mut facts) = (0, 0);
    for _ in 0..7500 {
        let r = plant.step().unwrap();
        iters += r.iterations;
        facts += r.factorizations;
    }
    println!("{:.3} s, {} iterations, {} factorisations", t.elapsed().as_secs_f64(), iters, facts);
}
