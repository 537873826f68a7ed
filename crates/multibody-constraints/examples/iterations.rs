//! Newton iterations and factorisations per step of the paper's two-links (2×50, 7.5 s).
use intrinsic_beam::Section;
use multibody_constraints::{samples, Plant, PlantSettings};
use nalgebra::Vector3;

fn main() {
    for three in [false, true] {
        let (s, w) = if three {
            (samples::paper_3d(Section::paper_3d(), 50, 0.0).unwrap(), Vector3::new(0.0, 1.0, 1.0))
        } else {
            (samples::paper_2d(Section::paper_2d(), 50, 0.0).unwrap(), Vector3::new(0.0, 1.0, 0.0))
        };
        let x = s.rigid_rotation_state(w, Vector3::zeros());
        let mut p = Plant::new(s, PlantSettings::default()).unwrap();
        p.set_state(&x).unwrap();
        let (mut it, mut f) = (0, 0);
        let t = std::time::Instant::now();
        for _ in 0..7500 {
            let r = p.step().unwrap();
            it += r.iterations;
            f += r.factorizations;
        }
        println!(
            "3d={three}: {:.2} iterations/step, {f} factorisations, {:.2} s",
            it as f64 / 7500.0,
            t.elapsed().as_secs_f64()
        );
    }
}
