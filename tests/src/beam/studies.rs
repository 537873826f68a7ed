//! Numerical experiments on single beams behind the `intrinsic-beam/*` verification cases and
//! the beam tests of this crate. Each returns measured numbers; the callers compare them with
//! tolerances.

use std::f64::consts::PI;

use nalgebra::{Matrix6, Vector3};

use super::dense_modes::{family, linear_modes, Family};
use intrinsic_beam::closed_form::{self, Supports};
use intrinsic_beam::samples::{self, euler_bernoulli_section, Sample};
use intrinsic_beam::{
    Beam, BeamError, BeamProblem, Components, Counters, EndCondition, ExplicitRk4,
    ImplicitMidpoint, Kinematics, LinearSolver, Mesh, NewtonSettings, Result, StepInput,
};

/// Tip position and rotation angle (`2 acos|ξ0|`) of a beam's last node.
pub fn tip(kinematics: &Kinematics) -> (Vector3<f64>, f64) {
    let n = kinematics.r.len() - 1;
    (kinematics.r[n], 2.0 * kinematics.xi[n][0].abs().min(1.0).acos())
}

fn simulate(sample: Sample, settings: NewtonSettings) -> Result<ImplicitMidpoint> {
    ImplicitMidpoint::new(sample.problem, sample.state, sample.kinematics, settings)
}

/// Result of [`energy_conservation`].
#[derive(Clone, Debug)]
pub struct EnergyStudy {
    /// `ε_h(0)`.
    pub initial_energy: f64,
    /// `max_n |ε_h(t_n) − ε_h(0)| / ε_h(0)`.
    pub max_relative_drift: f64,
    /// Largest tip deflection `|r_tip − L e1|` over the run, over `L`.
    pub max_tip_deflection: f64,
    /// Solver counters.
    pub counters: Counters,
}

/// Undamped, unloaded cantilever released from the arc of [`samples::cantilever_release`]:
/// energy drift over `steps` implicit-midpoint steps.
pub fn energy_conservation(
    components: Components,
    n_elements: usize,
    dt: f64,
    steps: usize,
) -> Result<EnergyStudy> {
    let mut sim =
        simulate(samples::cantilever_release(components, n_elements)?, NewtonSettings::default())?;
    let e0 = sim.energy();
    let mut drift: f64 = 0.0;
    let mut deflection: f64 = (tip(sim.kinematics()).0 - Vector3::x()).norm();
    for _ in 0..steps {
        sim.step(dt)?;
        drift = drift.max((sim.energy() - e0).abs() / e0);
        deflection = deflection.max((tip(sim.kinematics()).0 - Vector3::x()).norm());
    }
    Ok(EnergyStudy {
        initial_energy: e0,
        max_relative_drift: drift,
        max_tip_deflection: deflection,
        counters: sim.counters(),
    })
}

/// Result of [`damped_decay`].
#[derive(Clone, Debug)]
pub struct DecayStudy {
    /// Largest step-to-step energy increase relative to `ε_h(0)` (≤ round-off if monotone).
    pub max_relative_increase: f64,
    /// `ε_h(end)/ε_h(0)`.
    pub final_over_initial: f64,
    /// Largest `|Δε − dt P_damping| / ε_h(0)` over the steps (the discrete balance).
    pub max_balance_error: f64,
}

/// The released cantilever with diffusive damping `D2 = d I` only.
pub fn damped_decay(
    components: Components,
    n_elements: usize,
    d2: f64,
    dt: f64,
    steps: usize,
) -> Result<DecayStudy> {
    let mut sample = samples::cantilever_release(components, n_elements)?;
    let section = sample.problem.beam.section().clone().with_damping(
        Matrix6::zeros(),
        Matrix6::zeros(),
        Matrix6::identity() * d2,
    )?;
    let beam = Beam::new(section, sample.problem.beam.mesh().clone(), components)?;
    sample.problem = BeamProblem::new(
        beam,
        EndCondition::Clamped,
        EndCondition::Free,
        sample.problem.loads.clone(),
    )?;
    let mut sim = simulate(sample, NewtonSettings::default())?;
    let e0 = sim.energy();
    let (mut inc, mut bal): (f64, f64) = (0.0, 0.0);
    for _ in 0..steps {
        let old = sim.state().to_vec();
        let kin = sim.kinematics().clone();
        let e_old = sim.energy();
        sim.step(dt)?;
        let e_new = sim.energy();
        let input = StepInput {
            time: sim.time() - dt,
            dt,
            loads: &sim.problem().loads,
            node_quaternions: &kin.xi,
        };
        let p = sim.problem().beam.step_power(&input, &old, sim.state())?;
        inc = inc.max((e_new - e_old) / e0);
        bal = bal.max((e_new - e_old - dt * (p.damping + p.boundary + p.loads)).abs() / e0);
    }
    Ok(DecayStudy {
        max_relative_increase: inc,
        final_over_initial: sim.energy() / e0,
        max_balance_error: bal,
    })
}

/// One row of a frequency convergence study.
#[derive(Clone, Copy, Debug)]
pub struct FrequencyRow {
    /// Elements.
    pub n_elements: usize,
    /// Computed angular frequency.
    pub omega: f64,
    /// Closed-form value.
    pub exact: f64,
    /// `|ω − ω_exact| / ω_exact`.
    pub relative_error: f64,
}

/// First non-zero frequency of `fam` for the [`euler_bernoulli_section`] beam (`L = 1`) with
/// `supports`, on uniform meshes of `meshes` elements, against closed-form beam theory.
pub fn frequency_convergence(
    supports: Supports,
    fam: Family,
    meshes: &[usize],
) -> Result<Vec<FrequencyRow>> {
    let section = euler_bernoulli_section();
    let components = match fam {
        Family::Axial | Family::BendingE2 => Components::Planar,
        Family::Torsion | Family::BendingE3 => Components::Spatial,
    };
    let left = match supports {
        Supports::ClampedFree => EndCondition::Clamped,
        Supports::PinnedFree => EndCondition::Pinned,
        Supports::FreeFree => EndCondition::Free,
    };
    let exact = match fam {
        Family::Axial => closed_form::wave(supports, true, (100.0f64).sqrt(), 1.0, 1)[0],
        Family::Torsion => {
            let fixed = supports == Supports::ClampedFree;
            closed_form::wave(supports, fixed, (0.5f64 / 0.01).sqrt(), 1.0, 1)[0]
        }
        Family::BendingE2 => closed_form::bending(supports, 1.0, 1.0, 1.0, 1)[0],
        Family::BendingE3 => closed_form::bending(supports, 2.0, 1.0, 1.0, 1)[0],
    };
    let mut rows = Vec::new();
    for &n in meshes {
        let beam = Beam::new(section.clone(), Mesh::uniform(1.0, n)?, components)?;
        let problem = BeamProblem::new(beam, left.clone(), EndCondition::Free, Default::default())?;
        let modes = linear_modes(&problem)?;
        let omega = modes
            .iter()
            .filter(|m| m.omega > 1e-3 * exact && family(&problem.beam, m) == fam)
            .map(|m| m.omega)
            .next()
            .ok_or_else(|| BeamError::LinearSolve {
                reason: format!("no {fam:?} mode found with {n} elements"),
            })?;
        rows.push(FrequencyRow {
            n_elements: n,
            omega,
            exact,
            relative_error: (omega - exact).abs() / exact,
        });
    }
    Ok(rows)
}

/// Observed order `log2(e_{i}/e_{i+1})` of the last pair of rows (meshes doubling).
pub fn observed_order(rows: &[FrequencyRow]) -> f64 {
    let n = rows.len();
    if n < 2 {
        return f64::NAN;
    }
    let (a, b) = (&rows[n - 2], &rows[n - 1]);
    (a.relative_error / b.relative_error).ln() / (b.n_elements as f64 / a.n_elements as f64).ln()
}

/// Tip displacement `(u_x, u_z)/L` and rotation of the damped cantilever under the dead tip load
/// `PL²/EI = 1` ([`samples::cantilever_dead_tip_load`]) after `t_end` s with step `dt`.
pub fn dead_tip_load(
    components: Components,
    n_elements: usize,
    dt: f64,
    t_end: f64,
) -> Result<(f64, f64, f64)> {
    let mut sim = simulate(
        samples::cantilever_dead_tip_load(components, n_elements)?,
        NewtonSettings::default(),
    )?;
    let steps = (t_end / dt).round() as usize;
    for _ in 0..steps {
        sim.step(dt)?;
    }
    let (r, angle) = tip(sim.kinematics());
    Ok((r.x - 1.0, r.z, angle))
}

/// One stage of the roll-up study.
#[derive(Clone, Copy, Debug)]
pub struct RollUpRow {
    /// End rotation `θ = M L/EI` of the stage.
    pub theta: f64,
    /// Simulated tip displacement over `L`.
    pub simulated: (f64, f64),
    /// Exact circle.
    pub exact: (f64, f64),
    /// `max(|Δu_x|, |Δu_z|)/L`.
    pub error: f64,
}

/// Follower tip moment rolling the cantilever up to `θ = 2π` in `stages` held stages.
pub fn roll_up(
    components: Components,
    n_elements: usize,
    stages: usize,
    hold: f64,
    dt: f64,
) -> Result<Vec<RollUpRow>> {
    let theta_final = 2.0 * PI;
    let sample =
        samples::cantilever_follower_moment(components, n_elements, theta_final, stages, hold)?;
    let mut sim = simulate(sample, NewtonSettings::default())?;
    let mut rows = Vec::new();
    for (i, t_end) in samples::roll_up_schedule(stages, hold).into_iter().enumerate() {
        while sim.time() < t_end - 0.5 * dt {
            sim.step(dt)?;
        }
        let theta = theta_final * (i + 1) as f64 / stages as f64;
        let (r, _) = tip(sim.kinematics());
        let simulated = (r.x - 1.0, r.z);
        let exact = samples::roll_up_tip(theta);
        let error = (simulated.0 - exact.0).abs().max((simulated.1 - exact.1).abs());
        rows.push(RollUpRow { theta, simulated, exact, error });
    }
    Ok(rows)
}

/// Largest distance between node positions integrated in time and rebuilt in space from the
/// strains (eqs. 7, 10) after `t_end` of [`samples::cantilever_swing`].
pub fn time_space_gap(
    components: Components,
    n_elements: usize,
    dt: f64,
    t_end: f64,
) -> Result<f64> {
    let mut sim =
        simulate(samples::cantilever_swing(components, n_elements)?, NewtonSettings::default())?;
    let steps = (t_end / dt).round() as usize;
    for _ in 0..steps {
        sim.step(dt)?;
    }
    let kin = sim.kinematics();
    let rebuilt = Kinematics::from_strains(&sim.problem().beam, sim.state(), kin.xi[0], kin.r[0])?;
    Ok(kin.max_position_gap(&rebuilt))
}

/// Planar and spatial runs of the released cantilever: largest difference of the planar
/// components of the state and of the positions over `steps` steps.
pub fn planar_vs_spatial(n_elements: usize, dt: f64, steps: usize) -> Result<(f64, f64)> {
    let mut planar = simulate(
        samples::cantilever_release(Components::Planar, n_elements)?,
        NewtonSettings::default(),
    )?;
    let mut spatial = simulate(
        samples::cantilever_release(Components::Spatial, n_elements)?,
        NewtonSettings::default(),
    )?;
    let (mut dx, mut dr): (f64, f64) = (0.0, 0.0);
    for _ in 0..steps {
        planar.step(dt)?;
        spatial.step(dt)?;
        let (bp, bs) = (&planar.problem().beam, &spatial.problem().beam);
        for node in 0..bp.n_nodes() {
            dx = dx.max((bp.x1(planar.state(), node) - bs.x1(spatial.state(), node)).amax());
        }
        for e in 0..bp.n_elements() {
            dx = dx.max((bp.x2(planar.state(), e) - bs.x2(spatial.state(), e)).amax());
        }
        dr = dr.max(planar.kinematics().max_position_gap(spatial.kinematics()));
    }
    Ok((dx, dr))
}

/// Result of [`block_vs_sparse`].
#[derive(Clone, Debug)]
pub struct SolverStudy {
    /// `max |x_default − x_reference| / max(1, ‖x_reference‖∞)` over the run.
    pub max_relative_difference: f64,
    /// Newton iterations per step with the default settings (block-tridiagonal path).
    pub iterations_default: f64,
    /// Newton iterations per step of the reference (faer sparse LU, tolerance 1e-14).
    pub iterations_reference: f64,
    /// Name of the default run's linear solver at the end.
    pub solver: &'static str,
}

/// The released cantilever with the default settings (block-tridiagonal solver, one refresh
/// per step) against a reference converged to 1e-14 with faer's sparse LU, over `steps` steps.
pub fn block_vs_sparse(
    components: Components,
    n_elements: usize,
    dt: f64,
    steps: usize,
) -> Result<SolverStudy> {
    let sample = samples::cantilever_release(components, n_elements)?;
    let reference_settings = NewtonSettings {
        linear_solver: LinearSolver::SparseLu,
        tolerance: 1e-14,
        ..NewtonSettings::default()
    };
    let mut default = simulate(sample.clone(), NewtonSettings::default())?;
    let mut reference = simulate(sample, reference_settings)?;
    let mut diff: f64 = 0.0;
    for _ in 0..steps {
        default.step(dt)?;
        reference.step(dt)?;
        let scale = reference.state().iter().fold(1.0f64, |m, v| m.max(v.abs()));
        let d = default
            .state()
            .iter()
            .zip(reference.state())
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        diff = diff.max(d / scale);
    }
    let per_step = |c: Counters| c.newton_iterations as f64 / c.steps.max(1) as f64;
    Ok(SolverStudy {
        max_relative_difference: diff,
        iterations_default: per_step(default.counters()),
        iterations_reference: per_step(reference.counters()),
        solver: default.linear_solver_name(),
    })
}

/// Difference (max norm of the beam vector, end values excluded) between implicit midpoint with
/// step `dt` and RK4 with step `dt_rk4` after `t_end` of the swing with the
/// [`samples::soft_section`].
pub fn midpoint_vs_rk4(n_elements: usize, dt: f64, dt_rk4: f64, t_end: f64) -> Result<f64> {
    let sample =
        samples::cantilever_swing_with(samples::soft_section(), Components::Planar, n_elements)?;
    let mut rk =
        ExplicitRk4::new(sample.problem.clone(), sample.state.clone(), sample.kinematics.clone())?;
    let mut mid = simulate(sample, NewtonSettings::default())?;
    for _ in 0..(t_end / dt).round() as usize {
        mid.step(dt)?;
    }
    for _ in 0..(t_end / dt_rk4).round() as usize {
        rk.step(dt_rk4)?;
    }
    let n = mid.problem().beam.n_rows();
    Ok(mid.state()[..n]
        .iter()
        .zip(&rk.state()[..n])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max))
}

/// Largest relative residuals of the theory.md §2 identities over `cases` random states and
/// random valid sections (seeded): `[x1ᵀL1(x1)p, x1ᵀL2(x2)e − (L1(x1)x2)ᵀe, discrete energy
/// balance Σ mid·R − (Δε/dt − P)]`, each relative to the size of its terms.
pub fn identity_residuals(cases: usize, seed: u64) -> Result<[f64; 3]> {
    use intrinsic_beam::operators::{l1, l2};
    use intrinsic_beam::samples::random::{random_load, random_section, random_vec, seeded};
    use intrinsic_beam::{LoadFrame, Loads};
    use nalgebra::Vector6;
    use rand::Rng;
    let mut rng = seeded(seed);
    let mut worst = [0.0f64; 3];
    for case in 0..cases {
        let v = |rng: &mut rand_chacha::ChaCha8Rng| {
            Vector6::from_fn(|_, _| rng.random_range(-10.0..10.0))
        };
        let (x1, x2, p) = (v(&mut rng), v(&mut rng), v(&mut rng));
        worst[0] = worst[0].max(x1.dot(&(l1(&x1) * p)).abs() / (x1.norm_squared() * p.norm()));
        let a = x1.dot(&(l2(&x2) * p));
        let b = (l1(&x1) * x2).dot(&p);
        worst[1] = worst[1].max((a - b).abs() / (x1.norm() * x2.norm() * p.norm()));
        let comp = if case % 2 == 0 { Components::Planar } else { Components::Spatial };
        let section = random_section(&mut rng, comp, true, case % 3 != 0);
        let n = 1 + case % 6;
        let beam =
            Beam::new(section, Mesh::graded(1.0, n, 0.5 + rng.random::<f64>() * 2.0)?, comp)?;
        let load = random_load(&mut rng, comp);
        let loads = Loads::none()
            .with_point(n, LoadFrame::Dead, load)
            .with_distributed(LoadFrame::Follower, load);
        let kin = Kinematics::straight(&beam);
        let old = random_vec(&mut rng, beam.dim());
        let new = random_vec(&mut rng, beam.dim());
        let dt = 10f64.powf(rng.random_range(-4.0..0.0));
        let input = StepInput { time: 0.0, dt, loads: &loads, node_quaternions: &kin.xi };
        let b = beam.energy_balance(&input, &old, &new)?;
        worst[2] = worst[2].max(b.defect() / b.terms);
    }
    Ok(worst)
}
