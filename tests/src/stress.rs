//! Numerical stress experiments: long runs, large disturbances, extreme stiffness
//! ratios, joint angles near singular configurations and randomly generated structures.
//!
//! Every experiment is a list of *sub-runs*, each of which must end with finite results or a
//! clear (typed) error of the library: never a panic, never a silent NaN. [`guarded`] runs a
//! sub-run inside `catch_unwind` and classifies it ([`Status`]); every output a sub-run
//! reports is checked for finiteness ([`finite`]). `cargo xtask stress` prints and writes the
//! table; the cheap experiments are also registered as verification cases ([`cases`]; names
//! carry the crate they stress, `<crate>/stress-…`).

use std::f64::consts::PI;
use std::fmt::Display;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Instant;

use crate::beam::dense_modes::{family, linear_modes, Family};
use crate::multibody::studies::beam_rigid_rotation;
use intrinsic_beam::closed_form::{self, Supports};
use intrinsic_beam::{
    Beam, BeamProblem, Components, EndCondition, ImplicitMidpoint, Kinematics, Loads, Mesh,
    NewtonSettings, Section,
};
use modal_rom::{BasisSettings, StructureModel};
use mpc::{run, ControllerKind, ControllerSettings, PlantKind, RunResult, Scenario, Setup};
use multibody_constraints::null_space;
use multibody_constraints::{samples, Plant, PlantSettings};
use multibody_constraints::{End, EndRef, Frame, Freedom, Joint, JointKind, Support};
use multibody_constraints::{Placement, Structure, StructureBeam, StructureSettings};
use nalgebra::{Vector3, Vector4, Vector6};
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{Config, RngSeed, TestRunner};

use crate::{Case, CaseOutcome, Metric, Tier};

/// Problem sizes: `Quick` for CI and `cargo xtask stress --quick`, `Full` for the stress sizes of docs/stress.md.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Size {
    /// Seconds per experiment.
    Quick,
    /// The sizes (10⁵ steps, ω0 up to 3/1.5, 256 random structures).
    Full,
}

/// How a sub-run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Status {
    /// Finished; every reported output finite.
    Ok,
    /// Stopped with a typed error of the library (a clear error): the message.
    Error(String),
    /// A silent non-finite value in an output the library returned as valid: a defect.
    NonFinite(String),
    /// A panic (caught): a defect.
    Panic(String),
}

impl Status {
    /// `ok`, `error`, `NON-FINITE`, `PANIC`.
    pub fn label(&self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Error(_) => "error",
            Status::NonFinite(_) => "NON-FINITE",
            Status::Panic(_) => "PANIC",
        }
    }
}

/// What a sub-run is allowed to end with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Expect {
    /// It must finish (an error is a failure).
    Ok,
    /// A result or a clear error are both acceptable (e.g. an exactly singular joint).
    OkOrError,
}

/// One sub-run of an experiment.
#[derive(Clone, Debug)]
pub struct SubRun {
    /// What was run, e.g. `EA/EI = 1e8, 2000 steps`.
    pub label: String,
    /// How it ended.
    pub status: Status,
    /// What is acceptable.
    pub expect: Expect,
    /// Measured figures (bounded or report-only with an infinite tolerance).
    pub metrics: Vec<Metric>,
    /// Free text (what happened: stabilised or why not, which error, counts).
    pub note: String,
    /// Wall time (s).
    pub seconds: f64,
}

impl SubRun {
    /// Whether the sub-run is acceptable: no panic, no silent non-finite value, an error only
    /// when allowed, every bounded metric within its bound.
    pub fn pass(&self) -> bool {
        match &self.status {
            Status::Ok => self.metrics.iter().all(Metric::pass),
            Status::Error(_) => self.expect == Expect::OkOrError,
            Status::NonFinite(_) | Status::Panic(_) => false,
        }
    }
}

/// Why a sub-run stopped early.
#[derive(Clone, Debug)]
pub enum Stop {
    /// A typed error of the library.
    Error(String),
    /// A non-finite output.
    NonFinite(String),
}

/// A sub-run's result: figures and a note.
pub type Measured = Result<(Vec<Metric>, String), Stop>;

/// Converts a library error into a [`Stop::Error`].
fn lib<E: Display>(e: E) -> Stop {
    Stop::Error(e.to_string())
}

/// `Err(Stop::NonFinite)` naming `what` and the first non-finite entry.
pub fn finite<'a>(what: &str, values: impl IntoIterator<Item = &'a f64>) -> Result<(), Stop> {
    match values.into_iter().enumerate().find(|(_, v)| !v.is_finite()) {
        Some((i, v)) => Err(Stop::NonFinite(format!("{what}[{i}] = {v}"))),
        None => Ok(()),
    }
}

/// The message of a caught panic payload.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "(non-string panic payload)".to_string()
    }
}

/// Runs `f` inside `catch_unwind` and classifies it.
pub fn guarded(label: impl Into<String>, expect: Expect, f: impl FnOnce() -> Measured) -> SubRun {
    let start = Instant::now();
    let outcome = catch_unwind(AssertUnwindSafe(f));
    let seconds = start.elapsed().as_secs_f64();
    let (status, metrics, note) = match outcome {
        Ok(Ok((metrics, note))) => {
            // Figures are outputs too: a NaN among them is a silent NaN.
            match metrics.iter().find(|m| !m.value.is_finite()) {
                Some(m) => (
                    Status::NonFinite(format!("figure `{}` = {}", m.metric, m.value)),
                    metrics,
                    note,
                ),
                None => (Status::Ok, metrics, note),
            }
        }
        Ok(Err(Stop::Error(e))) => (Status::Error(e), Vec::new(), String::new()),
        Ok(Err(Stop::NonFinite(e))) => (Status::NonFinite(e), Vec::new(), String::new()),
        Err(payload) => (Status::Panic(panic_message(payload.as_ref())), Vec::new(), String::new()),
    };
    SubRun { label: label.into(), status, expect, metrics, note, seconds }
}

/// A report-only figure (never fails, but must be finite).
fn report(metric: impl Into<String>, value: f64) -> Metric {
    Metric::at_most(metric, value, f64::INFINITY)
}

/// A named experiment: a function producing its sub-runs at a [`Size`].
#[derive(Clone, Copy)]
pub struct Experiment {
    /// `group/name`, e.g. `long-run/cantilever`.
    pub name: &'static str,
    /// Part of `cargo xtask stress --quick`.
    pub in_quick: bool,
    /// Runs it.
    pub run: fn(Size) -> Vec<SubRun>,
}

/// Every stress experiment, in report order.
pub fn experiments() -> Vec<Experiment> {
    vec![
        Experiment { name: "long-run/cantilever", in_quick: true, run: long_run_cantilever },
        Experiment { name: "long-run/two-link-2d", in_quick: true, run: long_run_two_link },
        Experiment { name: "disturbance/2d", in_quick: true, run: disturbance_2d },
        Experiment { name: "disturbance/3d", in_quick: false, run: disturbance_3d },
        Experiment { name: "stiffness/cantilever", in_quick: true, run: stiffness_cantilever },
        Experiment { name: "stiffness/two-link-2d", in_quick: false, run: stiffness_two_link },
        Experiment { name: "singular/two-link-2d-folded", in_quick: true, run: singular_2d },
        Experiment { name: "singular/universal-3d", in_quick: true, run: singular_3d },
        Experiment { name: "random/structures", in_quick: true, run: random_structures },
    ]
}

// ---------------------------------------------------------------------------------------------
// Long runs

/// Checkpoints (step counts) at which the drift of a long run is recorded.
fn checkpoints(steps: usize) -> Vec<usize> {
    let mut c = Vec::new();
    let mut n = 1000;
    while n < steps {
        c.push(n);
        n *= 10;
    }
    c.push(steps);
    c
}

/// Drift figures of a long run: the final drift against the round-off bound, the drift at
/// each decade, and the growth exponent between the first and last decade.
///
/// Bound: each step is solved to a relative Newton update of 1e-12 and the energy identity
/// holds to round-off; the per-step energy error δ is a (nearly) random sign error of size
/// `tol · θ + ε · cond` ≲ 1e-13 (measured: 3.1e-12 over 10⁴ steps ⇒ δ ≈ 3e-14 for random-walk
/// growth), so after N steps `|Δε|/ε ≲ √N · δ` (1e-11 at N = 10⁵). The bound allows linear
/// growth of δ = 1e-15 per step on top: `√N·1e-13 + N·1e-15` (1.3e-10 at N = 10⁵).
fn drift_metrics(steps: usize, drift_at: &[(usize, f64)], out: &mut Vec<Metric>) {
    let n = steps as f64;
    let bound = n.sqrt() * 1e-13 + n * 1e-15;
    let last = drift_at.last().map(|d| d.1).unwrap_or(0.0);
    out.push(Metric::at_most(
        format!("relative energy drift after {steps} steps (bound √N·1e-13 + N·1e-15)"),
        last,
        bound,
    ));
    for (k, d) in drift_at {
        out.push(report(format!("drift after {k} steps"), *d));
    }
    if let (Some(a), Some(b)) = (drift_at.first(), drift_at.last()) {
        if b.0 > a.0 && a.1 > 0.0 && b.1 > 0.0 {
            out.push(report(
                "growth exponent d log(drift)/d log(N) (0.5: random walk, 1: systematic)",
                (b.1 / a.1).ln() / (b.0 as f64 / a.0 as f64).ln(),
            ));
        }
    }
}

/// The slender cantilever released from a 1 rad arc (intrinsic-beam's energy sample), with a
/// section whose axial stiffness is `ea` (EI = 1): undamped, unloaded.
fn released_cantilever(
    ea: f64,
    components: Components,
    n: usize,
) -> Result<ImplicitMidpoint, Stop> {
    let section =
        Section::from_diagonals([1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4], [ea, 1e4, 1e4, 0.5, 1.0, 1.0])
            .map_err(lib)?;
    let beam = Beam::new(section, Mesh::uniform(1.0, n).map_err(lib)?, components).map_err(lib)?;
    let mut state = vec![0.0; beam.dim()];
    for e in 0..n {
        beam.set_x2(&mut state, e, &Vector6::new(0.0, 0.0, 0.0, 0.0, -1.0, 0.0));
    }
    let kin =
        Kinematics::from_strains(&beam, &state, Vector4::new(1.0, 0.0, 0.0, 0.0), Vector3::zeros())
            .map_err(lib)?;
    let problem = BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())
        .map_err(lib)?;
    ImplicitMidpoint::new(problem, state, kin, NewtonSettings::default()).map_err(lib)
}

/// Steps a released cantilever, checking every state for finiteness; returns the drift at
/// the checkpoints and Newton iterations per step.
fn run_cantilever(
    sim: &mut ImplicitMidpoint,
    dt: f64,
    steps: usize,
) -> Result<(Vec<(usize, f64)>, f64), Stop> {
    let e0 = sim.energy();
    finite("initial energy", [e0].iter())?;
    let marks = checkpoints(steps);
    let mut drift = 0.0f64;
    let mut out = Vec::new();
    for s in 1..=steps {
        sim.step(dt).map_err(|e| Stop::Error(format!("step {s}: {e}")))?;
        let e = sim.energy();
        if !e.is_finite() {
            return Err(Stop::NonFinite(format!("energy at step {s} = {e}")));
        }
        drift = drift.max((e - e0).abs() / e0);
        if marks.contains(&s) {
            finite(&format!("state at step {s}"), sim.state())?;
            finite(
                &format!("tip position at step {s}"),
                sim.kinematics().r.last().map(|r| r.as_slice()).unwrap_or(&[]),
            )?;
            out.push((s, drift));
        }
    }
    let its = sim.counters().newton_iterations as f64 / steps.max(1) as f64;
    Ok((out, its))
}

fn long_run_cantilever(size: Size) -> Vec<SubRun> {
    let steps = if size == Size::Full { 100_000 } else { 10_000 };
    let mut runs = Vec::new();
    let comps: &[Components] = if size == Size::Full {
        &[Components::Planar, Components::Spatial]
    } else {
        &[Components::Planar]
    };
    for &c in comps {
        let label = format!("{c:?} cantilever, 20 el., dt 1e-3, {steps} steps, undamped");
        runs.push(guarded(label, Expect::Ok, || {
            let mut sim = released_cantilever(1e4, c, 20)?;
            let (drift, its) = run_cantilever(&mut sim, 1e-3, steps)?;
            let mut m = Vec::new();
            drift_metrics(steps, &drift, &mut m);
            m.push(report("Newton iterations per step", its));
            Ok((m, "released 1 rad arc, energy 0.5".into()))
        }));
    }
    runs
}

fn long_run_two_link(size: Size) -> Vec<SubRun> {
    let steps = if size == Size::Full { 100_000 } else { 10_000 };
    let label =
        format!("2D two-link 2×20 el., dt 1e-3, {steps} steps, undamped, link 2 at 4 rad/s");
    vec![guarded(label, Expect::Ok, || {
        let structure = samples::paper_2d(Section::paper_2d().undamped(), 20, 0.0).map_err(lib)?;
        let x = beam_rigid_rotation(
            &structure,
            1,
            Vector3::new(0.0, 4.0, 0.0),
            structure.reference()[1].r[0],
        );
        let mut plant = Plant::new(structure, PlantSettings::default()).map_err(lib)?;
        plant.set_state(&x).map_err(lib)?;
        let e0 = plant.energy();
        let elbow = plant.structure().joint_index("elbow").unwrap_or(1);
        let marks = checkpoints(steps);
        let (mut drift, mut gap, mut viol, mut angle) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut drift_at = Vec::new();
        let mut iters = 0usize;
        for s in 1..=steps {
            let r = plant.step().map_err(|e| Stop::Error(format!("step {s}: {e}")))?;
            iters += r.iterations;
            let e = plant.energy();
            if !e.is_finite() {
                return Err(Stop::NonFinite(format!("energy at step {s} = {e}")));
            }
            drift = drift.max((e - e0).abs() / e0);
            gap = gap.max(plant.joint_gap());
            viol = viol.max(r.velocity_violation);
            angle = angle.max(plant.joint_angles()[elbow].abs());
            if marks.contains(&s) {
                finite(&format!("state at step {s}"), plant.state())?;
                finite(&format!("joint angles at step {s}"), plant.joint_angles())?;
                drift_at.push((s, drift));
            }
        }
        let mut m = Vec::new();
        drift_metrics(steps, &drift_at, &mut m);
        // joined ends advance by identical increments: the gap is round-off (theory.md §3)
        m.push(Metric::at_most("max elbow gap (m)", gap, 1e-11));
        m.push(Metric::at_most("max velocity-row violation", viol, 1e-9));
        m.push(report("max |elbow angle| (deg)", angle.to_degrees()));
        m.push(report("Newton iterations per step", iters as f64 / steps as f64));
        Ok((m, String::new()))
    })]
}

// ---------------------------------------------------------------------------------------------
// Large disturbances

/// Figures and a verdict of one closed loop; every recorded output must be finite.
fn closed_loop_figures(r: &RunResult) -> Measured {
    for rec in &r.records {
        finite(&format!("q at t = {}", rec.t), &rec.q)?;
        finite(&format!("u at t = {}", rec.t), &rec.u)?;
        finite(&format!("tip at t = {}", rec.t), &rec.tip)?;
        finite(&format!("joint angles at t = {}", rec.t), &rec.joint_angles)?;
        finite(&format!("V at t = {}", rec.t), [rec.v_state].iter())?;
    }
    let s = &r.summary;
    let umax = r.records.iter().flat_map(|x| x.u.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    let excursion = s.max_orientation_deg.max(1e-300);
    let m = vec![
        report("V(T)/V(0)", s.v_ratio_final),
        report("rigid rate / ω0", s.rigid_rate_ratio),
        report("orientation error / largest excursion", s.orientation_error_deg / excursion),
        report("max |elbow angle| (deg)", s.max_joint_angle_deg),
        report("max |u|", umax),
        report("samples on relaxed retry", s.relaxed_samples as f64),
        report("samples on LMPC fallback", s.fallback_samples as f64),
        report("worst solve time per sample (s)", s.solve_time_worst_s),
        report("t_end (s)", s.t_end),
    ];
    let note = if let Some(e) = &s.error {
        format!("plant stopped at t = {:.2} s: {e}", s.t_end)
    } else if s.stabilised {
        "stabilised".to_string()
    } else {
        let mut why = Vec::new();
        if s.v_ratio_final >= 0.1 {
            why.push(format!("V(T)/V(0) = {:.3} ≥ 0.1", s.v_ratio_final));
        }
        if s.rigid_rate_ratio >= 0.05 {
            why.push(format!("rigid rate {:.3} ω0 ≥ 0.05 ω0", s.rigid_rate_ratio));
        }
        if s.orientation_error_deg > 0.2 * s.max_orientation_deg {
            why.push(format!(
                "orientation {:.1}° > 20% of {:.1}°",
                s.orientation_error_deg, s.max_orientation_deg
            ));
        }
        format!("not stabilised: {}", why.join("; "))
    };
    let note = if s.relaxed_samples + s.fallback_samples > 0 {
        format!("{note} ({} relaxed, {} fallback samples)", s.relaxed_samples, s.fallback_samples)
    } else {
        note
    };
    Ok((m, note))
}

/// Closed loops of one scenario at several ω0 and controllers.
fn disturbance_runs(
    three_d: bool,
    elements: usize,
    runs: &[(ControllerKind, f64, f64)],
    plant: PlantKind,
) -> Vec<SubRun> {
    let dim = if three_d { "3D" } else { "2D" };
    let setups: Vec<(f64, Result<Setup, String>)> = {
        let mut durations: Vec<f64> = runs.iter().map(|r| r.2).collect();
        durations.sort_by(f64::total_cmp);
        durations.dedup();
        durations
            .into_iter()
            .map(|d| {
                let built = catch_unwind(|| {
                    let mut sc = if three_d {
                        Scenario::paper_3d(elements)
                    } else {
                        Scenario::paper_2d(elements)
                    }
                    .map_err(|e| e.to_string())?;
                    sc.duration = d;
                    Setup::new(&sc).map_err(|e| e.to_string())
                })
                .unwrap_or_else(|p| Err(format!("panic: {}", panic_message(p.as_ref()))));
                (d, built)
            })
            .collect()
    };
    runs.iter()
        .map(|&(kind, w, duration)| {
            let label = format!(
                "{dim} {} ω0 = {w}, 2×{elements} el., {duration} s, {} plant",
                kind.name(),
                match plant {
                    PlantKind::Fe => "FE",
                    PlantKind::Rom => "ROM",
                }
            );
            let setup = setups.iter().find(|s| s.0 == duration).map(|s| &s.1);
            guarded(label, Expect::OkOrError, || {
                let setup = match setup {
                    Some(Ok(s)) => s,
                    Some(Err(e)) => return Err(Stop::Error(format!("setup: {e}"))),
                    None => return Err(Stop::Error("setup missing".into())),
                };
                let r = run(
                    setup,
                    w,
                    &ControllerSettings { kind, ..ControllerSettings::full_sqp() },
                    plant,
                )
                .map_err(lib)?;
                closed_loop_figures(&r)
            })
        })
        .collect()
}

fn disturbance_2d(size: Size) -> Vec<SubRun> {
    use ControllerKind::{Lmpc, Nmpc};
    match size {
        // The paper's mesh and horizon; ω0 beyond the paper's sweep (2.0).
        Size::Full => disturbance_runs(
            false,
            50,
            &[(Lmpc, 2.5, 7.5), (Lmpc, 3.0, 7.5), (Nmpc, 2.5, 7.5), (Nmpc, 3.0, 7.5)],
            PlantKind::Fe,
        ),
        // CI size: a coarser mesh (2×20) and 3 s.
        Size::Quick => disturbance_runs(false, 20, &[(Lmpc, 3.0, 3.0)], PlantKind::Fe),
    }
}

fn disturbance_3d(size: Size) -> Vec<SubRun> {
    use ControllerKind::{Lmpc, Nmpc};
    match size {
        // 2×20 elements (the 3D FE plant costs ~3× the 2D one per element) and a 4 s NMPC
        // horizon of simulation (3D SQP samples take 2–5 s each on this machine).
        Size::Full => disturbance_runs(
            true,
            20,
            &[(Lmpc, 1.0, 7.5), (Lmpc, 1.5, 7.5), (Nmpc, 1.5, 4.0)],
            PlantKind::Fe,
        ),
        Size::Quick => disturbance_runs(true, 10, &[(Lmpc, 1.5, 2.0)], PlantKind::Fe),
    }
}

// ---------------------------------------------------------------------------------------------
// Extreme stiffness ratios

fn stiffness_cantilever(size: Size) -> Vec<SubRun> {
    let (ratios, steps): (&[f64], usize) = match size {
        Size::Full => (&[1e4, 1e6, 1e8], 5000),
        Size::Quick => (&[1e8], 500),
    };
    let mut runs = Vec::new();
    for &ea in ratios {
        runs.push(guarded(
            format!("planar cantilever EA/EI = {ea:.0e}, 20 el., {steps} steps dt 1e-3"),
            Expect::Ok,
            || {
                let mut sim = released_cantilever(ea, Components::Planar, 20)?;
                let (drift, its) = run_cantilever(&mut sim, 1e-3, steps)?;
                let last = drift.last().map(|d| d.1).unwrap_or(0.0);
                // Same Newton tolerance as the default; a stiffer axial direction raises
                // cond(J) ∝ EA·dt²/h² but the energy identity still holds to the solve.
                Ok((
                    vec![
                        Metric::at_most("relative energy drift", last, 1e-10),
                        report("Newton iterations per step", its),
                    ],
                    String::new(),
                ))
            },
        ));
        runs.push(guarded(
            format!("modes, clamped–free, EA/EI = {ea:.0e}, 20 el."),
            Expect::Ok,
            || modes_figures(ea, 20),
        ));
    }
    if size == Size::Full {
        runs.push(guarded(
            format!("spatial cantilever EA/EI = 1e8, 20 el., {steps} steps dt 1e-3"),
            Expect::Ok,
            || {
                let mut sim = released_cantilever(1e8, Components::Spatial, 20)?;
                let (drift, its) = run_cantilever(&mut sim, 1e-3, steps)?;
                let last = drift.last().map(|d| d.1).unwrap_or(0.0);
                Ok((
                    vec![
                        Metric::at_most("relative energy drift", last, 1e-10),
                        report("Newton iterations per step", its),
                    ],
                    String::new(),
                ))
            },
        ));
    }
    runs
}

/// First bending and first axial frequency of the clamped–free cantilever against closed
/// forms (Euler–Bernoulli bending; axial wave `π/2 √(EA/m)`).
///
/// Tolerances: second-order FE error at 20 elements (≈ 6.6e-4 for bending, theory of
/// intrinsic-beam's frequency-convergence case) plus shear/rotary-inertia corrections of the
/// slender section (EI/(GA L²) = j/(m L²) = 1e-4, a few 1e-4 on the first mode): 5e-3. The
/// dense eigensolver's round-off `ε λmax/λ1` ≈ 1e-16 · (2N)²EA / 12 stays below 1e-5 at
/// EA = 1e8.
fn modes_figures(ea: f64, n: usize) -> Measured {
    let section =
        Section::from_diagonals([1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4], [ea, 1e4, 1e4, 0.5, 1.0, 1.0])
            .map_err(lib)?;
    let beam =
        Beam::new(section, Mesh::uniform(1.0, n).map_err(lib)?, Components::Planar).map_err(lib)?;
    let problem = BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())
        .map_err(lib)?;
    let modes = linear_modes(&problem).map_err(lib)?;
    for (i, m) in modes.iter().enumerate() {
        finite(&format!("mode {i} ω"), [m.omega].iter())?;
        finite(&format!("mode {i} φ1"), &m.phi1)?;
    }
    let bend = modes
        .iter()
        .find(|m| family(&problem.beam, m) == Family::BendingE2)
        .ok_or_else(|| Stop::Error("no bending mode found".into()))?;
    let axial = modes
        .iter()
        .find(|m| family(&problem.beam, m) == Family::Axial)
        .ok_or_else(|| Stop::Error("no axial mode found".into()))?;
    let bend_ref = closed_form::bending(Supports::ClampedFree, 1.0, 1.0, 1.0, 1)[0];
    let axial_ref = closed_form::wave(Supports::ClampedFree, true, ea.sqrt(), 1.0, 1)[0];
    Ok((
        vec![
            Metric::at_most(
                "first bending ω, relative error vs Euler–Bernoulli",
                (bend.omega - bend_ref).abs() / bend_ref,
                5e-3,
            ),
            Metric::at_most(
                "first axial ω, relative error vs π/2 √(EA/m)",
                (axial.omega - axial_ref).abs() / axial_ref,
                5e-3,
            ),
            report("first axial ω (rad/s)", axial.omega),
            report("modes", modes.len() as f64),
        ],
        String::new(),
    ))
}

/// The paper's 2D section with its axial stiffness raised to `ea` (EI = 1), undamped.
fn paper_2d_axial(ea: f64) -> Result<Section, Stop> {
    Section::from_diagonals(
        [1.0, 1.0, 1.0, 0.0, 1e-5, 0.0],
        [ea, f64::INFINITY, 1e5, f64::INFINITY, 1.0, f64::INFINITY],
    )
    .map_err(lib)
}

fn stiffness_two_link(size: Size) -> Vec<SubRun> {
    let steps = if size == Size::Full { 5000 } else { 500 };
    let mut runs = Vec::new();
    for ea in [1e3, 1e8] {
        runs.push(guarded(
            format!("2D two-link EA/EI = {ea:.0e}, 2×20 el., {steps} steps, link 2 at 4 rad/s"),
            Expect::Ok,
            || {
                let structure = samples::paper_2d(paper_2d_axial(ea)?, 20, 0.0).map_err(lib)?;
                let x = beam_rigid_rotation(
                    &structure,
                    1,
                    Vector3::new(0.0, 4.0, 0.0),
                    structure.reference()[1].r[0],
                );
                let model = StructureModel::new(&structure).map_err(lib)?;
                let basis = model.modes(&BasisSettings::default()).map_err(lib)?;
                finite("ω", basis.omega())?;
                let (o1, o2, o3) = basis.orthonormality_residuals();
                let mut plant = Plant::new(structure, PlantSettings::default()).map_err(lib)?;
                plant.set_state(&x).map_err(lib)?;
                let e0 = plant.energy();
                let mut drift = 0.0f64;
                for s in 1..=steps {
                    plant.step().map_err(|e| Stop::Error(format!("step {s}: {e}")))?;
                    drift = drift.max((plant.energy() - e0).abs() / e0);
                }
                finite("state", plant.state())?;
                let first_elastic = basis.omega().get(basis.n_rigid()).copied().unwrap_or(0.0);
                Ok((
                    vec![
                        Metric::at_most("relative energy drift", drift, 1e-10),
                        // SVD route: orthonormality to round-off × cond (modal-rom docs: 1e-14)
                        Metric::at_most("mode orthonormality residual", o1.max(o2).max(o3), 1e-8),
                        report("first elastic ω (rad/s)", first_elastic),
                        report("largest ω (rad/s)", basis.omega().last().copied().unwrap_or(0.0)),
                    ],
                    String::new(),
                ))
            },
        ));
    }
    runs
}

// ---------------------------------------------------------------------------------------------
// Joint angles near singular configurations

/// Modes, `G`/`Z` and a short undamped run with a rigid rotation about the root of a
/// structure built at some joint angle.
fn singular_figures(structure: Structure, omega: Vector3<f64>, steps: usize, dt: f64) -> Measured {
    let g = structure.constraint_matrix();
    let ns = null_space(&g).map_err(lib)?;
    let z = &ns.basis;
    let z_entries: Vec<f64> =
        (0..z.ncols()).flat_map(|j| (0..z.nrows()).map(move |i| z[(i, j)])).collect();
    finite("Z", &z_entries)?;
    let model = StructureModel::new(&structure).map_err(lib)?;
    let basis = model.modes(&BasisSettings::default()).map_err(lib)?;
    finite("ω", basis.omega())?;
    let (o1, o2, o3) = basis.orthonormality_residuals();
    let x = structure.rigid_rotation_state(omega, Vector3::zeros());
    let mut plant =
        Plant::new(structure, PlantSettings { dt, ..Default::default() }).map_err(lib)?;
    plant.set_state(&x).map_err(lib)?;
    let e0 = plant.energy();
    let mut drift = 0.0f64;
    for s in 1..=steps {
        plant.step().map_err(|e| Stop::Error(format!("step {s}: {e}")))?;
        let e = plant.energy();
        if !e.is_finite() {
            return Err(Stop::NonFinite(format!("energy at step {s} = {e}")));
        }
        drift = drift.max((e - e0).abs() / e0);
    }
    finite("state", plant.state())?;
    finite("joint angles", plant.joint_angles())?;
    let first_elastic = basis.omega().get(basis.n_rigid()).copied().unwrap_or(0.0);
    Ok((
        vec![
            // entries of G are O(1) direction cosines: |GZ| at round-off
            Metric::at_most("|GZ|", ns.residual, 1e-12),
            Metric::at_most("mode orthonormality residual", o1.max(o2).max(o3), 1e-8),
            Metric::at_most(format!("relative energy drift ({steps} steps)"), drift, 1e-10),
            report("rigid modes", basis.n_rigid() as f64),
            report("first elastic ω (rad/s)", first_elastic),
            report("max joint gap (m)", plant.joint_gap()),
        ],
        format!("rank G = {}", ns.rank),
    ))
}

fn singular_2d(size: Size) -> Vec<SubRun> {
    let (n, steps) = if size == Size::Full { (20, 2000) } else { (8, 200) };
    let angles: &[f64] = &[170.0, 179.0, 179.9, 179.999, 180.0];
    angles
        .iter()
        .map(|&deg| {
            let expect = if deg == 180.0 { Expect::OkOrError } else { Expect::Ok };
            guarded(
                format!("2D two-link folded to {deg}°, 2×{n} el., {steps} steps at ω0 = 1"),
                expect,
                move || {
                    let angle = if deg == 180.0 { PI } else { deg.to_radians() };
                    let s =
                        samples::paper_2d(Section::paper_2d().undamped(), n, angle).map_err(lib)?;
                    singular_figures(s, Vector3::new(0.0, 1.0, 0.0), steps, 1e-3)
                },
            )
        })
        .collect()
}

fn singular_3d(size: Size) -> Vec<SubRun> {
    let (n, steps) = if size == Size::Full { (20, 2000) } else { (6, 200) };
    let angles: &[f64] = &[80.0, 89.0, 89.9, 89.999, 90.0, 179.9];
    angles
        .iter()
        .map(|&deg| {
            let expect = if deg == 90.0 { Expect::OkOrError } else { Expect::Ok };
            guarded(
                format!("3D universal elbow at {deg}°, 2×{n} el., {steps} steps at ω0 = 1"),
                expect,
                move || {
                    let angle = if deg == 90.0 { PI / 2.0 } else { deg.to_radians() };
                    let s =
                        samples::paper_3d(Section::paper_3d().undamped(), n, angle).map_err(lib)?;
                    singular_figures(s, Vector3::new(0.0, 1.0, 1.0) / 2f64.sqrt(), steps, 1e-3)
                },
            )
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Randomly generated structures

/// One beam of a random tree.
#[derive(Clone, Debug)]
pub struct RandomBeam {
    /// Parent position in `[0, 1)`: the parent is beam `⌊frac · i⌋`.
    pub parent_frac: f64,
    /// Elements.
    pub elements: usize,
    /// Length.
    pub length: f64,
    /// Section: 0 paper-2d, 1 paper-3d, 2 slender, 3 paper-3d with EA ×1e3.
    pub section: u8,
    /// Attachment axis (local frame of the parent end) and angle (rad).
    pub axis: [f64; 3],
    /// Reference joint angle (rad).
    pub angle: f64,
    /// Joint kind if this beam creates its parent's joint: 0 weld, 1 ball, 2 hinge (global
    /// axis), 3 hinge (axis on the parent end), 4 universal, 5 custom.
    pub joint: u8,
    /// Hinge axis.
    pub hinge_axis: [f64; 3],
    /// Custom joint freedoms (translations, rotations): `true` = free.
    pub custom: [bool; 6],
    /// In planar structures, keep the random (usually non-planar) axes instead of e2.
    pub keep_axes: bool,
}

/// A random tree of 2–5 beams.
#[derive(Clone, Debug)]
pub struct RandomStructure {
    /// Planar or spatial.
    pub planar: bool,
    /// Support kind of the root: 0 weld, 1 hinge about e2, 2 ball, 3 universal.
    pub support: u8,
    /// Beams (the first is the root beam).
    pub beams: Vec<RandomBeam>,
}

fn random_beam() -> impl Strategy<Value = RandomBeam> {
    (
        (0.0f64..1.0, 1usize..=6, 0.3f64..2.0, 0u8..4),
        (prop::array::uniform3(-1.0f64..1.0), -PI..PI, 0u8..6),
        (prop::array::uniform3(-1.0f64..1.0), prop::array::uniform6(any::<bool>()), 0u8..8),
    )
        .prop_map(
            |(
                (parent_frac, elements, length, section),
                (axis, angle, joint),
                (hinge_axis, custom, k),
            )| {
                RandomBeam {
                    parent_frac,
                    elements,
                    length,
                    section,
                    axis,
                    angle,
                    joint,
                    hinge_axis,
                    custom,
                    keep_axes: k == 0,
                }
            },
        )
}

/// The proptest strategy of random structures.
pub fn random_structure() -> impl Strategy<Value = RandomStructure> {
    (any::<bool>(), 0u8..4, prop::collection::vec(random_beam(), 2..=5))
        .prop_map(|(planar, support, beams)| RandomStructure { planar, support, beams })
}

fn section_of(code: u8) -> intrinsic_beam::Result<Section> {
    Ok(match code {
        0 => Section::paper_2d(),
        1 => Section::paper_3d(),
        2 => intrinsic_beam::samples::slender_section(),
        _ => {
            let mut s = Section::paper_3d();
            s.compliance[(0, 0)] *= 1e-3;
            s.validate()?;
            s
        }
    })
}

impl RandomStructure {
    /// Builds the structure (beams `b0…`, joints `j<parent>` at parent ends, support `root`).
    pub fn build(&self) -> multibody_constraints::Result<Structure> {
        let components = if self.planar { Components::Planar } else { Components::Spatial };
        let e2 = [0.0, 1.0, 0.0];
        let planar_axis = |a: [f64; 3], keep: bool| if self.planar && !keep { e2 } else { a };
        let mut beams = Vec::new();
        let mut joints: Vec<Joint> = Vec::new();
        for (i, rb) in self.beams.iter().enumerate() {
            let section = section_of(rb.section)?;
            let beam = Beam::new(section, Mesh::uniform(rb.length, rb.elements)?, components)?;
            let name = format!("b{i}");
            let placement = if i == 0 {
                Placement::origin()
            } else {
                let p = ((rb.parent_frac * i as f64) as usize).min(i - 1);
                let jname = format!("j{p}");
                match joints.iter_mut().find(|j| j.name == jname) {
                    Some(j) => j.ends.push(EndRef::new(name.clone(), End::Start)),
                    None => {
                        let axis = planar_axis(rb.hinge_axis, rb.keep_axes);
                        let f = |b: bool| if b { Freedom::Free } else { Freedom::Rigid };
                        let kind = match rb.joint {
                            0 => JointKind::Weld,
                            1 => JointKind::Ball,
                            2 => JointKind::hinge_global(axis),
                            3 => JointKind::hinge_on_first(axis),
                            4 => JointKind::Universal,
                            _ => JointKind::Custom {
                                translation: [f(rb.custom[0]), f(rb.custom[1]), f(rb.custom[2])],
                                translation_frame: Frame::End(0),
                                rotation: [f(rb.custom[3]), f(rb.custom[4]), f(rb.custom[5])],
                                rotation_frame: Frame::End(0),
                                axes: None,
                            },
                        };
                        joints.push(Joint {
                            name: jname.clone(),
                            ends: vec![
                                EndRef::new(format!("b{p}"), End::End),
                                EndRef::new(name.clone(), End::Start),
                            ],
                            kind,
                        });
                    }
                }
                Placement::Attached {
                    joint: jname,
                    axis: planar_axis(rb.axis, rb.keep_axes),
                    angle: rb.angle,
                }
            };
            beams.push(StructureBeam::new(name, beam, placement));
        }
        let support = Support {
            name: "root".into(),
            end: EndRef::new("b0", End::Start),
            kind: match self.support {
                0 => JointKind::Weld,
                1 => JointKind::hinge_global(e2),
                2 => JointKind::Ball,
                _ => JointKind::Universal,
            },
        };
        Structure::new(beams, joints, vec![support], StructureSettings::default())
    }
}

/// Counts of the random-structure outcomes.
#[derive(Clone, Debug, Default)]
pub struct RandomCounts {
    /// Cases run.
    pub cases: usize,
    /// Build + G/Z + steps + modes all succeeded with finite output.
    pub ok: usize,
    /// Typed errors by stage: structure, null space, plant, steps, modes.
    pub errors: [usize; 5],
    /// Silent non-finite outputs.
    pub non_finite: usize,
    /// Panics.
    pub panics: usize,
    /// Largest `|GZ|` over the cases that reached it.
    pub max_gz: f64,
    /// Largest mode orthonormality residual.
    pub max_orthonormality: f64,
    /// First message of each error stage, and every defect (panic/non-finite) with its case.
    pub messages: Vec<String>,
}

/// Stage names of [`RandomCounts::errors`].
pub const STAGES: [&str; 5] = ["structure", "null space", "plant", "steps", "modes"];

/// One random case: `(stage of the error or 5 for ok, |GZ|, orthonormality)`.
fn random_case(rs: &RandomStructure, steps: usize) -> Result<(f64, f64), (usize, Stop)> {
    let s = rs.build().map_err(|e| (0, lib(e)))?;
    let ns = null_space(&s.constraint_matrix()).map_err(|e| (1, lib(e)))?;
    let gz = ns.residual;
    finite("|GZ|", [gz].iter()).map_err(|e| (1, e))?;
    let model_structure = s.clone();
    let mut plant = Plant::new(s, PlantSettings::default()).map_err(|e| (2, lib(e)))?;
    plant.set_gravity(Vector3::new(0.0, 0.0, -9.81)).map_err(|e| (2, lib(e)))?;
    for k in 1..=steps {
        plant.step().map_err(|e| (3, Stop::Error(format!("step {k}: {e}"))))?;
    }
    finite("state", plant.state()).map_err(|e| (3, e))?;
    finite("energy", [plant.energy()].iter()).map_err(|e| (3, e))?;
    for k in plant.kinematics() {
        finite("positions", k.r.iter().flat_map(|r| r.iter())).map_err(|e| (3, e))?;
    }
    let model = StructureModel::new(&model_structure).map_err(|e| (4, lib(e)))?;
    let basis = model.modes(&BasisSettings::default()).map_err(|e| (4, lib(e)))?;
    finite("ω", basis.omega()).map_err(|e| (4, e))?;
    let (o1, o2, o3) = basis.orthonormality_residuals();
    Ok((gz, o1.max(o2).max(o3)))
}

/// Runs `cases` random structures (fixed proptest seed) with `steps` plant steps each.
pub fn random_counts(cases: usize, steps: usize, seed: u64) -> RandomCounts {
    let config =
        Config { rng_seed: RngSeed::Fixed(seed), failure_persistence: None, ..Config::default() };
    let mut runner = TestRunner::new(config);
    let strategy = random_structure();
    let mut c = RandomCounts { cases, ..Default::default() };
    let mut first = [false; 5];
    for i in 0..cases {
        let rs = match strategy.new_tree(&mut runner) {
            Ok(t) => t.current(),
            Err(e) => {
                c.messages.push(format!("case {i}: generator failed: {e}"));
                continue;
            }
        };
        match catch_unwind(AssertUnwindSafe(|| random_case(&rs, steps))) {
            Ok(Ok((gz, orth))) => {
                c.ok += 1;
                c.max_gz = c.max_gz.max(gz);
                c.max_orthonormality = c.max_orthonormality.max(orth);
            }
            Ok(Err((stage, Stop::Error(m)))) => {
                c.errors[stage] += 1;
                if !first[stage] {
                    first[stage] = true;
                    c.messages.push(format!("first {} error (case {i}): {m}", STAGES[stage]));
                }
            }
            Ok(Err((stage, Stop::NonFinite(m)))) => {
                c.non_finite += 1;
                c.messages.push(format!("NON-FINITE at {} (case {i}): {m}; {rs:?}", STAGES[stage]));
            }
            Err(p) => {
                c.panics += 1;
                c.messages.push(format!("PANIC (case {i}): {}; {rs:?}", panic_message(p.as_ref())));
            }
        }
    }
    c
}

/// Seed of the random structures.
pub const RANDOM_SEED: u64 = 0x5eed_0008;

fn random_structures(size: Size) -> Vec<SubRun> {
    let (cases, steps) = if size == Size::Full { (256, 20) } else { (32, 5) };
    let label = format!(
        "{cases} random trees of 2–5 beams, {steps} steps under gravity, seed {RANDOM_SEED:#x}"
    );
    let mut defects = Vec::new();
    let mut run = guarded(label, Expect::Ok, || {
        let c = random_counts(cases, steps, RANDOM_SEED);
        defects = c
            .messages
            .iter()
            .filter(|m| m.starts_with("PANIC") || m.starts_with("NON"))
            .cloned()
            .collect();
        let mut m = vec![
            Metric::at_most("panics", c.panics as f64, 0.0),
            Metric::at_most("silent non-finite outputs", c.non_finite as f64, 0.0),
            report("ok (build, G/Z, steps, modes)", c.ok as f64),
        ];
        for (k, n) in c.errors.iter().enumerate() {
            m.push(report(format!("typed error at {}", STAGES[k]), *n as f64));
        }
        // G holds O(1) direction cosines: |GZ| is round-off
        m.push(Metric::at_most("max |GZ|", c.max_gz, 1e-12));
        m.push(Metric::at_most("max mode orthonormality residual", c.max_orthonormality, 1e-8));
        // the generator mostly produces valid trees: at least a quarter must run through
        m.push(Metric::at_least("fraction ok", c.ok as f64 / cases as f64, 0.25));
        Ok((m, c.messages.join(" | ")))
    });
    if !defects.is_empty() && run.status == Status::Ok {
        run.status = Status::NonFinite(defects.join(" | "));
    }
    vec![run]
}

// ---------------------------------------------------------------------------------------------
// Verification cases

/// Flattens sub-runs into verification metrics: each sub-run's figures (prefixed by its
/// label), and a failing metric for a panic, a silent non-finite value or an unexpected error.
pub fn to_case(runs: Vec<SubRun>) -> CaseOutcome {
    let mut out = Vec::new();
    for r in runs {
        match &r.status {
            Status::Ok => out.extend(
                r.metrics
                    .into_iter()
                    .map(|m| Metric { metric: format!("{}: {}", r.label, m.metric), ..m }),
            ),
            Status::Error(e) if r.expect == Expect::OkOrError => {
                out.push(report(format!("{}: clear error: {e}", r.label), 0.0))
            }
            Status::Error(e) => {
                out.push(Metric::at_most(format!("{}: error: {e}", r.label), 1.0, 0.0))
            }
            Status::NonFinite(e) => {
                out.push(Metric::at_most(format!("{}: non-finite: {e}", r.label), 1.0, 0.0))
            }
            Status::Panic(e) => {
                out.push(Metric::at_most(format!("{}: panic: {e}", r.label), 1.0, 0.0))
            }
        }
    }
    Ok(out)
}

/// The stress verification cases (quick: CI sizes; full: the sizes of docs/stress.md).
pub fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "intrinsic-beam/stress-stiffness",
            tier: Tier::Quick,
            run: || to_case(stiffness_cantilever(Size::Quick)),
        },
        Case {
            name: "modal-rom/stress-singular-2d",
            tier: Tier::Quick,
            run: || to_case(singular_2d(Size::Quick)),
        },
        Case {
            name: "modal-rom/stress-singular-3d",
            tier: Tier::Quick,
            run: || to_case(singular_3d(Size::Quick)),
        },
        Case {
            name: "multibody-constraints/stress-random",
            tier: Tier::Quick,
            run: || to_case(random_structures(Size::Quick)),
        },
        Case {
            name: "mpc/stress-disturbance-2d",
            tier: Tier::Quick,
            run: || to_case(disturbance_2d(Size::Quick)),
        },
        Case {
            name: "intrinsic-beam/stress-long-run",
            tier: Tier::Full,
            run: || to_case(long_run_cantilever(Size::Full)),
        },
        Case {
            name: "multibody-constraints/stress-long-run",
            tier: Tier::Full,
            run: || to_case(long_run_two_link(Size::Full)),
        },
        Case {
            name: "intrinsic-beam/stress-stiffness-full",
            tier: Tier::Full,
            run: || to_case(stiffness_cantilever(Size::Full)),
        },
        Case {
            name: "multibody-constraints/stress-stiffness",
            tier: Tier::Full,
            run: || to_case(stiffness_two_link(Size::Full)),
        },
        Case {
            name: "modal-rom/stress-singular-full",
            tier: Tier::Full,
            run: || {
                let mut r = singular_2d(Size::Full);
                r.extend(singular_3d(Size::Full));
                to_case(r)
            },
        },
        Case {
            name: "multibody-constraints/stress-random-full",
            tier: Tier::Full,
            run: || to_case(random_structures(Size::Full)),
        },
        Case {
            name: "mpc/stress-disturbance-full",
            tier: Tier::Full,
            run: || {
                let mut r = disturbance_2d(Size::Full);
                r.extend(disturbance_3d(Size::Full));
                to_case(r)
            },
        },
    ]
}

// ---------------------------------------------------------------------------------------------
// Scene-parser fuzzing

/// Fuzzing of the scene parser and loader (`flexmpc::scene::parse_str` / `load_str`):
/// deterministic inputs (a seeded stream per case index, so any case can be replayed
/// alone and parallel runs give the same counts), each run inside `catch_unwind`.
///
/// Inputs: (a) arbitrary text (random bytes, lossily decoded), (b) TOML-like token soup from
/// the scene vocabulary, (c) 1–4 mutations of a shipped scene: bit flips, byte replacements,
/// line deletions/duplications/swaps, truncation, value replacements with extreme numbers
/// (NaN, ±inf, 1e308, 5e-324, negatives, huge integers), key/name replacements and inserted
/// lines.
pub mod scene_fuzz {
    use std::panic::{catch_unwind, AssertUnwindSafe};
    use std::path::Path;

    use super::panic_message;

    /// Shipped scenes (`scenes/`), the seeds of the mutations: every structure kind and both
    /// paper closed loops.
    pub const SHIPPED: [(&str, &str); 8] = [
        ("ball-joint-3.toml", include_str!("../../scenes/ball-joint-3.toml")),
        ("cantilever.toml", include_str!("../../scenes/cantilever.toml")),
        ("l-frame.toml", include_str!("../../scenes/l-frame.toml")),
        ("paper-2d.toml", include_str!("../../scenes/paper-2d.toml")),
        ("paper-2d-modes.toml", include_str!("../../scenes/paper-2d-modes.toml")),
        ("paper-2d-mpc.toml", include_str!("../../scenes/paper-2d-mpc.toml")),
        ("paper-3d.toml", include_str!("../../scenes/paper-3d.toml")),
        ("paper-3d-mpc.toml", include_str!("../../scenes/paper-3d-mpc.toml")),
    ];

    /// Largest total element count a fuzz case may load. The scene loader itself has **no**
    /// cap (`elements = 1000000000` is accepted by `parse_str` and `load_str` would try to
    /// allocate the mesh and the sparse step matrix), so cases above this are counted as
    /// [`Class::OverCap`] and not loaded.
    pub const MAX_ELEMENTS: usize = 1000;

    /// The fuzzer's draws on the workspace's seeded generator
    /// ([`intrinsic_beam::samples::random::seeded`], ChaCha8).
    #[derive(Clone, Debug)]
    pub struct Draws(rand_chacha::ChaCha8Rng);

    impl Draws {
        /// Seeded stream.
        pub fn new(seed: u64) -> Self {
            Self(intrinsic_beam::samples::random::seeded(seed))
        }

        /// Next 64 random bits.
        pub fn next_u64(&mut self) -> u64 {
            rand::RngCore::next_u64(&mut self.0)
        }

        /// Uniform in `0..n` (`n = 0` is treated as 1).
        pub fn below(&mut self, n: usize) -> usize {
            rand::Rng::random_range(&mut self.0, 0..n.max(1))
        }

        /// One element of a non-empty slice.
        pub fn pick<T: Copy>(&mut self, items: &[T]) -> T {
            items[self.below(items.len())]
        }
    }

    /// Extreme and awkward values for value replacements.
    pub const EXTREMES: [&str; 44] = [
        "nan",
        "-nan",
        "+nan",
        "inf",
        "-inf",
        "+inf",
        "0",
        "-0",
        "0.0",
        "-0.0",
        "1e308",
        "-1e308",
        "1.7976931348623157e308",
        "5e-324",
        "-5e-324",
        "1e-300",
        "-1",
        "-1.0",
        "1",
        "2",
        "3",
        "1e9",
        "1000000000",
        "4294967296",
        "18446744073709551615",
        "9223372036854775807",
        "-9223372036854775808",
        "123456789012",
        "1e-3",
        "0.5",
        "\"\"",
        "\"x\"",
        "true",
        "[]",
        "[1, 2]",
        "{}",
        "[nan, nan, nan]",
        "[1e308, 1e308, 1e308]",
        "[0.0, 0.0, 0.0]",
        "100000",
        "5000",
        "999",
        "[[1.0, 0.0], [0.5, nan]]",
        "0x10",
    ];

    /// Keys, table names and values of the scene format.
    pub const VOCABULARY: [&str; 62] = [
        "beams",
        "sections",
        "joints",
        "supports",
        "loads",
        "torques",
        "initial",
        "rigid",
        "run",
        "output",
        "name",
        "section",
        "length",
        "elements",
        "origin",
        "rotation",
        "attach",
        "joint",
        "axis",
        "angle_deg",
        "kind",
        "ends",
        "end",
        "frame",
        "translation",
        "rotation_frame",
        "axes",
        "preset",
        "undamped",
        "mass",
        "stiffness",
        "d2",
        "stiffness_factor",
        "kappa0",
        "beam",
        "node",
        "force",
        "moment",
        "amplitude",
        "ramp",
        "table",
        "value",
        "omega",
        "center",
        "dt",
        "duration",
        "output_every",
        "newton_tolerance",
        "plot",
        "title",
        "description",
        "components",
        "allow_disconnected",
        "gravity",
        "planar",
        "spatial",
        "weld",
        "ball",
        "hinge",
        "universal",
        "custom",
        "paper-2d",
    ];

    /// Other tokens of the token soup.
    const TOKENS: [&str; 24] = [
        " = ",
        "\n",
        "[",
        "]",
        "[[",
        "]]",
        "{",
        "}",
        ",",
        ".",
        "\"",
        "'",
        "#",
        "=",
        " ",
        "\"paper-3d\"",
        "\"a:end\"",
        "\"b:start\"",
        "\"global\"",
        "\"follower\"",
        "\"dead\"",
        "\"free\"",
        "\"rigid\"",
        "\"\"\"",
    ];

    /// What kind of input a case is.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Source {
        /// Random bytes.
        Bytes,
        /// Token soup.
        Tokens,
        /// Mutated shipped scene.
        Mutation,
    }

    /// The input of case `index` of the stream `seed`.
    pub fn generate(seed: u64, index: u64) -> (Source, String) {
        let mut rng = Draws::new(seed ^ index.wrapping_mul(0xD1B5_4A32_D192_ED03));
        rng.next_u64();
        match rng.below(10) {
            0 => {
                let n = rng.below(600);
                let bytes: Vec<u8> = (0..n)
                    .map(|_| {
                        // half printable ASCII (reaches deeper into the TOML grammar)
                        if rng.below(2) == 0 {
                            (32 + rng.below(95)) as u8
                        } else {
                            rng.below(256) as u8
                        }
                    })
                    .collect();
                (Source::Bytes, String::from_utf8_lossy(&bytes).into_owned())
            }
            1 => {
                let n = rng.below(120);
                let mut s = String::new();
                for _ in 0..n {
                    match rng.below(4) {
                        0 => s.push_str(rng.pick(&VOCABULARY)),
                        1 => s.push_str(rng.pick(&EXTREMES)),
                        _ => s.push_str(rng.pick(&TOKENS)),
                    }
                }
                (Source::Tokens, s)
            }
            _ => {
                let base = rng.pick(&SHIPPED).1;
                let mut text = base.to_string();
                // 1 mutation half of the time, 2 a quarter, 3–4 the rest: deep enough to
                // reach the loader and the plant, varied enough to break the syntax
                let count = match rng.below(8) {
                    0..=3 => 1,
                    4 | 5 => 2,
                    _ => 3 + rng.below(2),
                };
                for _ in 0..count {
                    text = mutate(&mut rng, &text);
                }
                (Source::Mutation, text)
            }
        }
    }

    /// Byte ranges of number-like tokens in `line`.
    fn numbers(line: &str) -> Vec<(usize, usize)> {
        let b = line.as_bytes();
        let mut out = Vec::new();
        let mut i = 0;
        while i < b.len() {
            if b[i].is_ascii_digit()
                || ((b[i] == b'-' || b[i] == b'+') && i + 1 < b.len() && b[i + 1].is_ascii_digit())
            {
                let start = i;
                i += 1;
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b"._+-".contains(&b[i])) {
                    i += 1;
                }
                out.push((start, i));
            } else {
                i += 1;
            }
        }
        out
    }

    /// One random mutation of `text`.
    pub fn mutate(rng: &mut Draws, text: &str) -> String {
        let lines: Vec<&str> = text.lines().collect();
        let mut lines: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
        let n = lines.len().max(1);
        match rng.below(14) {
            0 => {
                // bit flip
                let mut bytes = text.as_bytes().to_vec();
                if !bytes.is_empty() {
                    let i = rng.below(bytes.len());
                    bytes[i] ^= 1 << rng.below(8);
                }
                return String::from_utf8_lossy(&bytes).into_owned();
            }
            1 => {
                // random byte
                let mut bytes = text.as_bytes().to_vec();
                if !bytes.is_empty() {
                    let i = rng.below(bytes.len());
                    bytes[i] = rng.below(256) as u8;
                }
                return String::from_utf8_lossy(&bytes).into_owned();
            }
            2 if !lines.is_empty() => {
                lines.remove(rng.below(n));
            }
            3 if !lines.is_empty() => {
                let i = rng.below(n);
                let l = lines[i].clone();
                lines.insert(i, l);
            }
            4 if lines.len() > 1 => {
                let (i, j) = (rng.below(n), rng.below(n));
                lines.swap(i, j);
            }
            5 => {
                // truncate
                let mut cut = rng.below(text.len() + 1);
                while !text.is_char_boundary(cut) {
                    cut -= 1;
                }
                return text[..cut].to_string();
            }
            6..=10 => {
                // value replacement with an extreme (the main mutation)
                let candidates: Vec<usize> =
                    (0..lines.len()).filter(|&i| !numbers(&lines[i]).is_empty()).collect();
                if !candidates.is_empty() {
                    let i = rng.pick(&candidates);
                    let nums = numbers(&lines[i]);
                    let (a, b) = rng.pick(&nums);
                    let v = rng.pick(&EXTREMES);
                    lines[i].replace_range(a..b, v);
                }
            }
            11 => {
                // whole right-hand side replaced
                let candidates: Vec<usize> =
                    (0..lines.len()).filter(|&i| lines[i].contains('=')).collect();
                if !candidates.is_empty() {
                    let i = rng.pick(&candidates);
                    let key = lines[i].split('=').next().unwrap_or("").to_string();
                    let v = if rng.below(2) == 0 {
                        rng.pick(&EXTREMES).to_string()
                    } else {
                        format!("\"{}\"", rng.pick(&VOCABULARY))
                    };
                    lines[i] = format!("{key}= {v}");
                }
            }
            12 => {
                // key or quoted name replaced by another word of the format
                let candidates: Vec<usize> =
                    (0..lines.len()).filter(|&i| lines[i].contains('=')).collect();
                if !candidates.is_empty() {
                    let i = rng.pick(&candidates);
                    let rest =
                        lines[i].split_once('=').map(|x| x.1.to_string()).unwrap_or_default();
                    lines[i] = format!("{} ={rest}", rng.pick(&VOCABULARY));
                }
            }
            _ => {
                // an inserted line: a table header, a key = extreme value, or a copied line
                let i = rng.below(n + 1).min(lines.len());
                let new = match rng.below(3) {
                    0 => format!(
                        "[{}{}]",
                        if rng.below(2) == 0 { "[" } else { "" },
                        rng.pick(&VOCABULARY)
                    ),
                    1 => format!("{} = {}", rng.pick(&VOCABULARY), rng.pick(&EXTREMES)),
                    _ => lines.get(rng.below(n)).cloned().unwrap_or_default(),
                };
                lines.insert(i, new);
            }
        }
        let mut out = lines.join("\n");
        out.push('\n');
        out
    }

    /// How a case ended.
    #[derive(Clone, Debug, PartialEq)]
    pub enum Class {
        /// `parse_str` returned an error.
        ParseError,
        /// Parsed, but asked for more than [`MAX_ELEMENTS`] elements: not loaded.
        OverCap,
        /// `load_str` returned an error.
        LoadError,
        /// Loaded; the first plant step returned an error (a clear error).
        StepError,
        /// Loaded and stepped once, every state and energy finite.
        Ok,
        /// Loaded from finite but extreme values (e.g. `gravity = [0, 0, 1e308]`, a rigid
        /// rotation `center` at 1e308) whose energy overflows to ±inf: the loader checks
        /// finiteness, not magnitudes. Counted and reported; state and positions stayed finite.
        Overflow(String),
        /// A non-finite initial or stepped state or position without an error: a defect.
        NonFinite(String),
        /// A panic: a defect (stage and message).
        Panic(String),
    }

    impl Class {
        /// Short label.
        pub fn label(&self) -> &'static str {
            match self {
                Class::ParseError => "parse error",
                Class::OverCap => "over the fuzz element cap",
                Class::LoadError => "load error",
                Class::StepError => "loaded, step error",
                Class::Ok => "ok (loaded, stepped)",
                Class::Overflow(_) => "loaded, energy overflows (extreme finite input)",
                Class::NonFinite(_) => "NON-FINITE",
                Class::Panic(_) => "PANIC",
            }
        }

        /// Panic or silent non-finite value.
        pub fn is_defect(&self) -> bool {
            matches!(self, Class::NonFinite(_) | Class::Panic(_))
        }
    }

    /// Parses, loads (if under the cap) and steps once, each stage inside `catch_unwind`.
    pub fn check(text: &str) -> Class {
        let file = Path::new("fuzz.toml");
        let parsed = match catch_unwind(|| flexmpc::scene::parse_str(file, text)) {
            Err(p) => return Class::Panic(format!("parse_str: {}", panic_message(p.as_ref()))),
            Ok(Err(_)) => return Class::ParseError,
            Ok(Ok(spec)) => spec,
        };
        let elements =
            parsed.beams.iter().fold(0usize, |acc, b| acc.saturating_add(b.get_ref().elements));
        if elements > MAX_ELEMENTS {
            return Class::OverCap;
        }
        let scene = match catch_unwind(|| flexmpc::scene::load_str(file, text)) {
            Err(p) => return Class::Panic(format!("load_str: {}", panic_message(p.as_ref()))),
            Ok(Err(_)) => return Class::LoadError,
            Ok(Ok(scene)) => scene,
        };
        let mut plant = match catch_unwind(AssertUnwindSafe(|| scene.plant())) {
            Err(p) => return Class::Panic(format!("plant: {}", panic_message(p.as_ref()))),
            Ok(Err(_)) => return Class::LoadError,
            Ok(Ok(plant)) => plant,
        };
        let stepped = catch_unwind(AssertUnwindSafe(|| {
            let p = &plant;
            if let Some(v) = p.state().iter().find(|v| !v.is_finite()) {
                return Err(Class::NonFinite(format!("initial state entry {v}")));
            }
            let (e, v) = (p.energy(), p.potential_energy());
            let overflow = (!(e.is_finite() && v.is_finite()))
                .then(|| format!("initial energy {e:e}, gravity potential {v:e}"));
            let step = plant.step();
            let p = &plant;
            if step.is_ok() {
                if let Some(v) = p.state().iter().find(|v| !v.is_finite()) {
                    return Err(Class::NonFinite(format!("state after one step: {v}")));
                }
                if p.kinematics()
                    .iter()
                    .flat_map(|k| k.r.iter())
                    .any(|r| !r.iter().all(|x| x.is_finite()))
                {
                    return Err(Class::NonFinite("positions after one step".into()));
                }
            }
            match (overflow, step) {
                (Some(o), s) => Err(Class::Overflow(format!(
                    "{o}; first step {}",
                    if s.is_ok() { "ok, state finite" } else { "returned an error" }
                ))),
                (None, Err(_)) => Err(Class::StepError),
                (None, Ok(_)) => Ok(()),
            }
        }));
        match stepped {
            Err(p) => Class::Panic(format!("plant step: {}", panic_message(p.as_ref()))),
            Ok(Err(c)) => c,
            Ok(Ok(())) => Class::Ok,
        }
    }
}
