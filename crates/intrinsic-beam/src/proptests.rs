//! Property tests of the identities of theory.md §2 over random states and random valid
//! sections (fixed proptest seed, 128 cases).

use nalgebra::{Matrix6, Vector3, Vector6};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

use crate::beam::{Beam, StepInput};
use crate::components::Components;
use crate::kinematics::Kinematics;
use crate::loads::{LoadFrame, Loads};
use crate::mesh::Mesh;
use crate::operators::{e_matrix, l1, l2};
use crate::samples::random::{random_load, random_section, random_vec, seeded};
use rand::Rng;

fn config() -> Config {
    Config {
        cases: 128,
        rng_seed: RngSeed::Fixed(0x5eed_2026),
        failure_persistence: None,
        ..Config::default()
    }
}

fn v6() -> impl Strategy<Value = Vector6<f64>> {
    prop::array::uniform6(-10.0f64..10.0).prop_map(Vector6::from)
}

proptest! {
    #![proptest_config(config())]

    /// `x1ᵀ L1(x1) p = 0` for every `p` (in particular `p = M x1` for any `M`).
    #[test]
    fn l1_is_energy_neutral(x1 in v6(), p in v6()) {
        let val = x1.dot(&(l1(&x1) * p));
        prop_assert!(val.abs() <= 1e-12 * (1.0 + x1.norm() * x1.norm() * p.norm()));
    }

    /// `x1ᵀ L2(x2) e = (L1(x1) x2)ᵀ e` for all `x1, x2, e`.
    #[test]
    fn l2_is_adjoint_of_l1(x1 in v6(), x2 in v6(), e in v6()) {
        let a = x1.dot(&(l2(&x2) * e));
        let b = (l1(&x1) * x2).dot(&e);
        prop_assert!((a - b).abs() <= 1e-12 * (1.0 + x1.norm() * x2.norm() * e.norm()));
    }

    /// `x1ᵀ E x2 − x2ᵀ Eᵀ x1 = 0` for any `κ0`.
    #[test]
    fn e_terms_cancel(x1 in v6(), x2 in v6(), k in prop::array::uniform3(-5.0f64..5.0)) {
        let e = e_matrix(&Vector3::from(k));
        let val = x1.dot(&(e * x2)) - x2.dot(&(e.transpose() * x1));
        prop_assert!(val.abs() <= 1e-12 * (1.0 + x1.norm() * x2.norm()));
    }

    /// Discrete energy balance of the staggered scheme for random valid sections (full
    /// matrices, curvature, damping), random graded meshes, loads and any pair of states:
    /// `Σ mid·R = (ε(new) − ε(old))/dt − (boundary + load + damping power)`.
    #[test]
    fn discrete_energy_balance(seed in any::<u64>(), planar in any::<bool>(), n in 1usize..7, grading in 0.3f64..3.0) {
        let comp = if planar { Components::Planar } else { Components::Spatial };
        let mut rng = seeded(seed);
        let section = random_section(&mut rng, comp, true, seed % 3 != 0);
        let beam = Beam::new(section, Mesh::graded(0.7 + rng.random::<f64>(), n, grading).unwrap(), comp).unwrap();
        let load = random_load(&mut rng, comp);
        let loads = Loads::none().with_point(n, LoadFrame::Dead, load).with_distributed(LoadFrame::Follower, load * 0.5);
        let kin = Kinematics::straight(&beam);
        let old = random_vec(&mut rng, beam.dim());
        let new = random_vec(&mut rng, beam.dim());
        let dt = 10f64.powf(rng.random_range(-4.0..0.0));
        let input = StepInput { time: 0.0, dt, loads: &loads, node_quaternions: &kin.xi };
        let b = beam.energy_balance(&input, &old, &new).unwrap();
        // round-off of a sum of O(dim) terms of size ≤ 1 + Σ|mid·R|
        prop_assert!(b.defect() <= 1e-12 * (1.0 + b.terms));
    }

    /// The linear operator `A` is skew on the beam unknowns; the damping operator (D1 = 0)
    /// is symmetric negative semidefinite; `B` is symmetric positive semidefinite.
    #[test]
    fn linear_operators_structure(seed in any::<u64>(), planar in any::<bool>(), n in 1usize..6) {
        let comp = if planar { Components::Planar } else { Components::Spatial };
        let mut rng = seeded(seed);
        let mut section = random_section(&mut rng, comp, true, true);
        section.d1 = Matrix6::zeros();
        let beam = Beam::new(section, Mesh::graded(1.0, n, 2.0).unwrap(), comp).unwrap();
        let ops = beam.linear_operators();
        let dense = |list: &[(usize, usize, f64)], r: usize, c: usize| {
            let mut m = nalgebra::DMatrix::<f64>::zeros(r, c);
            for &(i, j, v) in list { if i < r && j < c { m[(i, j)] += v; } }
            m
        };
        let a = dense(&ops.a, ops.n_rows, ops.n_rows);
        prop_assert!((&a + a.transpose()).abs().max() < 1e-13);
        let nn = beam.k() * beam.n_nodes();
        let d = dense(&ops.damping, nn, nn);
        prop_assert!((&d - d.transpose()).abs().max() < 1e-12);
        prop_assert!(nalgebra::SymmetricEigen::new(d).eigenvalues.max() < 1e-12);
        let b = dense(&ops.b, ops.dim, ops.dim);
        prop_assert!((&b - b.transpose()).abs().max() < 1e-14);
        prop_assert!(nalgebra::SymmetricEigen::new(b).eigenvalues.min() > -1e-12);
    }
}
