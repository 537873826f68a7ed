//! Seeded random data for property checks and verification cases: random valid sections (full
//! SPD matrices, curvature, dissipative damping) and random states.
//!
//! The generator is `rand_chacha`'s ChaCha8 ([`seeded`]): its stream is fixed by the seed
//! alone, on every platform and in every release of the crate, so a check that draws from it
//! sees the same numbers on every run. The functions take any [`rand::Rng`].

use nalgebra::{Matrix6, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::components::{Components, OUT_OF_PLANE_INDICES};
use crate::kinematics::Kinematics;
use crate::rotation::quaternion_step;
use crate::section::Section;

/// The workspace's seeded generator: ChaCha8 from a 64-bit seed.
///
/// ```
/// use intrinsic_beam::samples::random::{random_vec, seeded};
/// assert_eq!(random_vec(&mut seeded(7), 4), random_vec(&mut seeded(7), 4));
/// ```
pub fn seeded(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A random vector of length `n` with entries uniform in `[−1, 1)`.
pub fn random_vec(rng: &mut impl Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// A random load (or end value) for `components`: six entries uniform in `[−1, 1)`, the
/// out-of-plane ones then zeroed if planar.
pub fn random_load(rng: &mut impl Rng, components: Components) -> Vector6<f64> {
    let mut v = Vector6::from_fn(|_, _| rng.random_range(-1.0..1.0));
    if components == Components::Planar {
        for j in OUT_OF_PLANE_INDICES {
            v[j] = 0.0;
        }
    }
    v
}

/// Turns every node quaternion of `kinematics` by an angle uniform in `[−1, 1)` rad about an
/// axis with entries uniform in `[−1, 1)` (about e2 if planar), so that dead loads and end
/// rotations see a non-trivial configuration.
pub fn random_rotations(rng: &mut impl Rng, kinematics: &mut Kinematics, components: Components) {
    for xi in kinematics.xi.iter_mut() {
        let axis = match components {
            Components::Planar => Vector3::new(0.0, 1.0, 0.0),
            Components::Spatial => Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0)),
        };
        *xi = quaternion_step(xi, &axis, rng.random_range(-1.0..1.0));
    }
}

fn random_spd(rng: &mut impl Rng, components: Components, shift: f64) -> Matrix6<f64> {
    let idx = components.indices();
    let mut l = Matrix6::zeros();
    for &i in idx {
        for &j in idx {
            l[(i, j)] = rng.random_range(-1.0..1.0);
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

/// A random valid section: full SPD `M`, `C` (eigenvalues at least 0.5), random `κ0` (about
/// e2 only if planar) if `curved`, and if `damping` random dissipative damping (`D0 ≤ 0`,
/// `D2 ≥ 0`, `D1` symmetric with its diagonal halved).
pub fn random_section(
    rng: &mut impl Rng,
    components: Components,
    damping: bool,
    curved: bool,
) -> Section {
    let mut s = Section::from_diagonals([1.0; 6], [1.0; 6]).expect("valid");
    s.mass = random_spd(rng, components, 0.5);
    s.compliance = random_spd(rng, components, 0.5);
    if curved {
        s.kappa0 = match components {
            Components::Planar => Vector3::new(0.0, rng.random_range(-1.0..1.0), 0.0),
            Components::Spatial => Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0)),
        };
    }
    if damping {
        s.d0 = -random_spd(rng, components, 0.0) * 0.1;
        s.d2 = random_spd(rng, components, 0.0) * 0.1;
        let d1 = random_spd(rng, components, 0.0) * 0.1;
        s.d1 = d1 - Matrix6::from_diagonal(&d1.diagonal()) * 0.5;
    }
    s.validate().expect("a random section is valid by construction");
    s
}
