//! Deterministic random data for property checks: a small LCG, random valid sections
//! (full SPD matrices, curvature, dissipative damping) and random states.

use nalgebra::{Matrix6, Vector3};

use crate::components::Components;
use crate::section::Section;

/// Deterministic linear congruential generator (fixed seeds, reproducible).
pub(crate) struct Lcg(u64);

impl Lcg {
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407))
    }

    pub(crate) fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64) / ((1u64 << 53) as f64)
    }

    pub(crate) fn uniform(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next_f64()
    }
}

/// A random vector of length `n` with entries in (−1, 1).
pub(crate) fn random_vec(rng: &mut Lcg, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect()
}

fn random_spd(rng: &mut Lcg, components: Components, shift: f64) -> Matrix6<f64> {
    let idx = components.indices();
    let mut l = Matrix6::zeros();
    for &i in idx {
        for &j in idx {
            l[(i, j)] = rng.uniform(-1.0, 1.0);
        }
    }
    let mut m = l * l.transpose();
    for &i in idx {
        m[(i, i)] += shift;
    }
    if components == Components::Planar {
        // out-of-plane block: uncoupled, positive
        for i in [1, 3, 5] {
            m[(i, i)] = 1.0 + shift;
        }
    }
    m
}

/// A random valid section: full SPD `M`, `C`, random `κ0` (about e2 only if planar) and
/// optionally random dissipative damping (`D0 ≤ 0`, `D2 ≥ 0`, `D1` symmetric).
pub(crate) fn random_section(
    rng: &mut Lcg,
    components: Components,
    damping: bool,
    curved: bool,
) -> Section {
    let mut s = Section::from_diagonals([1.0; 6], [1.0; 6]).expect("valid");
    s.mass = random_spd(rng, components, 0.5);
    s.compliance = random_spd(rng, components, 0.5);
    if curved {
        s.kappa0 = match components {
            Components::Planar => Vector3::new(0.0, rng.uniform(-1.0, 1.0), 0.0),
            Components::Spatial => {
                Vector3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0))
            }
        };
    }
    if damping {
        s.d0 = -random_spd(rng, components, 0.0) * 0.1;
        s.d2 = random_spd(rng, components, 0.0) * 0.1;
        let d1 = random_spd(rng, components, 0.0) * 0.1;
        s.d1 = d1 - Matrix6::from_diagonal(&d1.diagonal()) * 0.5;
    }
    s.validate().expect("random section is valid");
    s
}
