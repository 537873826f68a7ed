//! Residual, Jacobian and energy-balance checks of the per-beam discretisation.

use super::*;
use crate::kinematics::Kinematics;
use crate::loads::{Amplitude, DistributedLoad, PointLoad};
use crate::samples::random::{random_load, random_rotations, random_section, random_vec, seeded};
use crate::section::Section;
use nalgebra::{DMatrix, Vector3};
use rand::Rng;

fn setup(
    seed: u64,
    components: Components,
    damping: bool,
) -> (Beam, Loads, Kinematics, Vec<f64>, Vec<f64>) {
    let mut rng = seeded(seed);
    // odd seeds: curved sections; even seeds: straight (E keeps its ẽ1 block)
    let section = random_section(&mut rng, components, damping, seed % 2 == 1);
    let mesh = Mesh::graded(1.3, 5, 2.0).unwrap();
    let beam = Beam::new(section, mesh, components).unwrap();
    let loads = Loads {
        point: vec![
            PointLoad {
                node: 5,
                frame: LoadFrame::Dead,
                value: random_load(&mut rng, components),
                amplitude: Amplitude::Constant,
            },
            PointLoad {
                node: 2,
                frame: LoadFrame::Follower,
                value: random_load(&mut rng, components),
                amplitude: Amplitude::Ramp { duration: 1.0 },
            },
        ],
        distributed: vec![DistributedLoad {
            frame: LoadFrame::Dead,
            value: random_load(&mut rng, components),
            amplitude: Amplitude::Constant,
        }],
    };
    let mut kin = Kinematics::straight(&beam);
    random_rotations(&mut rng, &mut kin, components);
    let old = random_vec(&mut rng, beam.dim());
    let new = random_vec(&mut rng, beam.dim());
    (beam, loads, kin, old, new)
}

/// `Σ mid_i R_i = (ε(new) − ε(old))/dt − P(mid)` for *any* old/new: the discrete energy
/// identity behind exact conservation (theory.md §2).
#[test]
fn residual_energy_identity_holds_for_any_states() {
    for (seed, comp) in
        [(1, Components::Spatial), (2, Components::Planar), (3, Components::Spatial)]
    {
        let (beam, loads, kin, old, new) = setup(seed, comp, true);
        let input = StepInput { time: 0.3, dt: 0.01, loads: &loads, node_quaternions: &kin.xi };
        let b = beam.energy_balance(&input, &old, &new).unwrap();
        // terms are O(100) (1/dt × O(1) energies): round-off level is ~1e-12
        assert!(b.defect() < 1e-10 * (1.0 + b.energy_rate.abs()), "{} vs {}", b.work, b.rate());
    }
}

/// The beam's Jacobian assembled densely from its pattern and values.
fn assembled_jacobian(
    beam: &Beam,
    input: &StepInput<'_>,
    old: &[f64],
    new: &[f64],
) -> DMatrix<f64> {
    let mut pattern = Vec::new();
    beam.jacobian_pattern(0, 0, &mut pattern);
    assert_eq!(pattern.len(), beam.jacobian_nnz());
    let mut vals = vec![0.0; beam.jacobian_nnz()];
    beam.jacobian_values(input, old, new, &mut vals).unwrap();
    let mut jac = DMatrix::zeros(beam.n_rows(), beam.dim());
    for (&(r, c), v) in pattern.iter().zip(&vals) {
        jac[(r, c)] += v;
    }
    jac
}

/// Central finite differences (step 1e-6) of the step residual with respect to `new`.
fn fd_jacobian(beam: &Beam, input: &StepInput<'_>, old: &[f64], new: &[f64]) -> DMatrix<f64> {
    let eps = 1e-6;
    let mut fd = DMatrix::zeros(beam.n_rows(), beam.dim());
    let (mut rp, mut rm) = (vec![0.0; beam.n_rows()], vec![0.0; beam.n_rows()]);
    for j in 0..beam.dim() {
        let (mut xp, mut xm) = (new.to_vec(), new.to_vec());
        xp[j] += eps;
        xm[j] -= eps;
        beam.step_residual(input, old, &xp, &mut rp).unwrap();
        beam.step_residual(input, old, &xm, &mut rm).unwrap();
        for i in 0..beam.n_rows() {
            fd[(i, j)] = (rp[i] - rm[i]) / (2.0 * eps);
        }
    }
    fd
}

/// The analytic Jacobian matches central finite differences of the residual.
#[test]
fn jacobian_matches_finite_differences() {
    for (seed, comp) in [
        (4, Components::Spatial),
        (5, Components::Planar),
        (7, Components::Spatial),
        (8, Components::Planar),
    ] {
        let (beam, loads, kin, old, new) = setup(seed, comp, true);
        let input = StepInput { time: 0.3, dt: 0.01, loads: &loads, node_quaternions: &kin.xi };
        let jac = assembled_jacobian(&beam, &input, &old, &new);
        let fd = fd_jacobian(&beam, &input, &old, &new);
        // Exact except the dead-load rotation derivative, approximated to O(dt |ω|)
        // relative (≈ 1e-2 here on entries of size O(1)); everything else to FD error 1e-7.
        let diff = (&jac - &fd).abs().max();
        assert!(diff < 2e-2, "max |J − FD| = {diff}");
        let no_dead = Loads { point: vec![loads.point[1].clone()], distributed: vec![] };
        let input = StepInput { loads: &no_dead, ..input };
        let jac = assembled_jacobian(&beam, &input, &old, &new);
        let fd = fd_jacobian(&beam, &input, &old, &new);
        // residual entries O(1e3) (1/dt scaling): central FD error ~ 1e-6 relative
        let diff = (&jac - &fd).abs().max();
        assert!(diff < 1e-5 * (1.0 + jac.abs().max()), "max |J − FD| = {diff}");
    }
}

/// The planar kernels are the in-plane restriction of the 6-component operators.
#[test]
fn planar_ops_match_spatial_operators() {
    let mut rng = seeded(11);
    let c = Components::Planar;
    for _ in 0..20 {
        let a: Vec<f64> = random_vec(&mut rng, 3);
        let b: Vec<f64> = random_vec(&mut rng, 3);
        let kappa = rng.random_range(-1.0..1.0);
        let (a3, b3) =
            (nalgebra::Vector3::from_column_slice(&a), nalgebra::Vector3::from_column_slice(&b));
        let (a6, b6) = (c.embed(&a), c.embed(&b));
        let k0 = Vector3::new(0.0, kappa, 0.0);
        let pairs = [
            (planar_ops::l1_times(&a3, &b3), l1_times(&a6, &b6)),
            (planar_ops::l2_times(&a3, &b3), l2_times(&a6, &b6)),
            (planar_ops::l1t_times(&a3, &b3), l1t_times(&a6, &b6)),
            (planar_ops::e_times(kappa, &a3), e_times(&k0, &a6)),
            (planar_ops::et_times(kappa, &a3), et_times(&k0, &a6)),
        ];
        for (p, s6) in pairs {
            assert!((c.embed(p.as_slice()) - s6).amax() < 1e-15, "{p:?} vs {s6:?}");
        }
    }
}

/// Jacobian vs finite differences with rigid and massless directions (midpoint weight 1
/// on algebraic unknowns): the paper's 2D section, spatial, damped, follower loads.
#[test]
fn jacobian_matches_finite_differences_for_dae_sections() {
    let mut rng = seeded(21);
    let beam =
        Beam::new(Section::paper_2d(), Mesh::graded(1.0, 4, 2.0).unwrap(), Components::Spatial)
            .unwrap();
    assert!((0..beam.dim()).any(|i| beam.is_algebraic(i) && i < beam.n_rows()));
    let loads = Loads::none().with_point(
        4,
        LoadFrame::Follower,
        Vector6::from_fn(|_, _| rng.random_range(-1.0..1.0)),
    );
    let kin = Kinematics::straight(&beam);
    let old = random_vec(&mut rng, beam.dim());
    let new = random_vec(&mut rng, beam.dim());
    let input = StepInput { time: 0.1, dt: 0.01, loads: &loads, node_quaternions: &kin.xi };
    let jac = assembled_jacobian(&beam, &input, &old, &new);
    let worst = (&jac - fd_jacobian(&beam, &input, &old, &new)).abs().max();
    // entries up to ~1e2 (h/dt scaling); central differences: ~1e-7 absolute
    assert!(worst < 1e-5, "max |J − FD| = {worst}");
}

/// At rest with no loads the Jacobian is `B/dt − A·diag(μ)`, and `A` is skew on the beam
/// unknowns; the damping operator is symmetric negative semidefinite.
#[test]
fn linear_operators_are_consistent_and_skew() {
    let (beam, _, kin, _, _) = setup(6, Components::Spatial, true);
    let ops = beam.linear_operators();
    let dense = |list: &[(usize, usize, f64)], r: usize, c: usize| {
        let mut m = DMatrix::zeros(r, c);
        for &(i, j, v) in list {
            m[(i, j)] += v;
        }
        m
    };
    let a = dense(&ops.a, ops.n_rows, ops.dim);
    let b = dense(&ops.b, ops.dim, ops.dim);
    let sq = a.view((0, 0), (ops.n_rows, ops.n_rows)).into_owned();
    assert!((&sq + sq.transpose()).abs().max() < 1e-14);
    let none = Loads::none();
    let dt = 0.1;
    let input = StepInput { time: 0.0, dt, loads: &none, node_quaternions: &kin.xi };
    let zero = vec![0.0; beam.dim()];
    let mut pattern = Vec::new();
    beam.jacobian_pattern(0, 0, &mut pattern);
    let mut vals = vec![0.0; beam.jacobian_nnz()];
    beam.jacobian_values(&input, &zero, &zero, &mut vals).unwrap();
    let jac = dense(
        &pattern.iter().zip(&vals).map(|(&(r, c), &v)| (r, c, v)).collect::<Vec<_>>(),
        ops.n_rows,
        ops.dim,
    );
    let damp = dense(&ops.damping, ops.n_rows, ops.dim);
    let mut expect = b.rows(0, ops.n_rows) / dt - a - &damp;
    for j in 0..ops.dim {
        let mu = beam.midpoint_weight(j);
        for i in 0..ops.n_rows {
            let bpart = if j < ops.n_rows { b[(i, j)] / dt } else { 0.0 };
            expect[(i, j)] = bpart + (expect[(i, j)] - bpart) * mu;
        }
    }
    assert!((&jac - &expect).abs().max() < 1e-12 * (1.0 + jac.abs().max()));
    // Without D1 (whose boundary term ½[x1ᵀ D1 x1] is not sign-definite) the damping
    // operator is symmetric negative semidefinite.
    let mut section = beam.section().clone();
    section.d1 = Matrix6::zeros();
    let beam = Beam::new(section, beam.mesh().clone(), beam.components()).unwrap();
    let ops = beam.linear_operators();
    let nn = beam.k() * beam.n_nodes();
    let d = dense(&ops.damping, nn, nn);
    assert!((&d - d.transpose()).abs().max() < 1e-12);
    let max_eig = nalgebra::SymmetricEigen::new(d).eigenvalues.max();
    assert!(max_eig < 1e-12, "damping not dissipative: {max_eig}");
}
