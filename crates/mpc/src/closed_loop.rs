//! The closed loop: sample → project the plant state onto the modes → solve → hold the
//! control for `τs` on the plant; time series, snapshots, per-sample reports and the summary
//! metrics; sweeps over `ω0` in parallel.

use crate::controller::{
    Controller, ControllerKind, ControllerSettings, SampleReport, SolveTiming, Strategy,
};
use crate::dynamics::RomDynamics;
use crate::error::{invalid, Result};
use crate::exact_dynamics::{default_link_elastic_modes, ExactDynamics, ModelKind};
use crate::plant::{relative_angle, ExactPlant, PlantKind, SimPlant};
use crate::scenario::{ratio, Setup};
use crate::validity::JointMonitor;
use crate::weights::{ControlGrid, Weights};
use intrinsic_beam::Kinematics;
use nalgebra::Vector4;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// One row of the time series (every `output_interval`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// Time (s).
    pub t: f64,
    /// State part of the cost (34), `½(q − q_r)ᵀQ(q − q_r)`, of the projected plant state.
    pub v_state: f64,
    /// Control held over the interval that starts here.
    pub u: Vec<f64>,
    /// Joint angles (rad), structure order (supports: angle of the end relative to its
    /// reference). Planar: signed; spatial: relative rotation angle in `[0, π]`.
    pub joint_angles: Vec<f64>,
    /// Global position of the last node of the last beam.
    pub tip: [f64; 3],
    /// Mechanical energy of the plant (kinetic + strain: the FE plant's, or the reduced
    /// model's `½|q1|² + ½|q2|²`).
    pub energy: f64,
    /// Per [`crate::Scenario::references`] command: rotation angle between the commanded and
    /// the plant's rotation of the joint (rad; empty without commands).
    pub command_errors: Vec<f64>,
    /// Modal state `q_a` (projected FE state, or the ROM plant's state).
    pub q: Vec<f64>,
}

/// The deformed structure at one time: node positions and section orientations, and the
/// plant's state for velocities and sectional loads.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// Time (s).
    pub t: f64,
    /// `positions[beam][node]` (global).
    pub positions: Vec<Vec<[f64; 3]>>,
    /// `orientations[beam][node]`: the node quaternion `ξ` (scalar first; section frame →
    /// global, `docs/theory.md §1`). The FE plant's own; for the ROM plant its modal
    /// quaternion field, or the reference orientations when the model has no quaternion
    /// states.
    #[serde(default)]
    pub orientations: Vec<Vec<[f64; 4]>>,
    /// The full FE state vector (ordering of `docs/theory.md §2`: node velocities `x1` and
    /// element forces and moments `x2`, section frame) — the FE plant's, or for the ROM plant
    /// the fields rebuilt from its modal state. Kept in memory only (not serialised).
    #[serde(skip)]
    pub state: Vec<f64>,
}

/// Largest rotation error (deg) of a joint command at the end of a reconfiguration for
/// [`RunSummary::stabilised`].
pub const COMMAND_TOLERANCE_DEG: f64 = 1.0;

/// Largest plant energy at the end of a reconfiguration, relative to its peak, for
/// [`RunSummary::stabilised`].
pub const ENERGY_RATIO_LIMIT: f64 = 0.01;

/// The summary of one closed loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// Disturbance magnitude `ω0` (rad/s) per disturbed axis.
    pub omega0: f64,
    /// `nmpc` or `lmpc`.
    pub controller: String,
    /// `fe` or `rom`.
    pub plant: String,
    /// The controller's reduced model: `paper` or `exact-joints` (the ROM plant is this
    /// model too).
    pub model: String,
    /// `V(T)/V(0)`, state part of the cost (T = end of the run).
    pub v_ratio_final: f64,
    /// Largest `|joint angle|` of the joints between links (deg).
    pub max_joint_angle_deg: f64,
    /// `|root link angle|` at T (deg).
    pub orientation_error_deg: f64,
    /// Largest `|root link angle|` over the run (deg).
    pub max_orientation_deg: f64,
    /// Rigid rotation rate at T over its initial value (`ω0`): the norm of the rigid modes'
    /// velocity coordinates `q1`, relative to t = 0.
    pub rigid_rate_ratio: f64,
    /// The criterion at T, and the run completed. Without joint commands (stabilisation):
    /// `rigid_rate_ratio < 0.05`, orientation error within 20% of the largest excursion,
    /// `V(T)/V(0) < 0.1`. With joint commands ([`crate::Scenario::references`],
    /// reconfiguration): every command met to [`COMMAND_TOLERANCE_DEG`] and
    /// `energy_ratio_final` below [`ENERGY_RATIO_LIMIT`].
    pub stabilised: bool,
    /// Plant energy (kinetic + strain) at T over its largest value during the run.
    pub energy_ratio_final: f64,
    /// Per joint command: rotation angle between the commanded and the plant's rotation at T
    /// (deg; empty without commands).
    pub command_errors_deg: Vec<f64>,
    /// Worst per-sample solve time (s): the calling thread's CPU
    /// ([`SampleReport::solve_time`]; with `ControllerSettings::parallel_intervals` on it
    /// misses the pool's work, see [`Self::solve_cpu_per_thread_worst_s`]).
    pub solve_time_worst_s: f64,
    /// Median per-sample solve time (s), the same measure.
    pub solve_time_median_s: f64,
    /// Threads each solve ran on ([`crate::SolveTiming::solve_threads`], largest over the
    /// samples).
    #[serde(default)]
    pub solve_threads: usize,
    /// Worst per-sample CPU time per thread (s, [`crate::SolveTiming::solve_cpu_per_thread`]:
    /// all threads' CPU over `solve_threads` with the intervals in parallel, else the calling
    /// thread's CPU).
    #[serde(default)]
    pub solve_cpu_per_thread_worst_s: f64,
    /// Median per-sample CPU time per thread (s), the same measure.
    #[serde(default)]
    pub solve_cpu_per_thread_median_s: f64,
    /// Worst per-sample wall time of the solve (s, [`crate::SolveTiming::solve_wall_time`]).
    #[serde(default)]
    pub solve_wall_worst_s: f64,
    /// Median per-sample wall time of the solve (s).
    #[serde(default)]
    pub solve_wall_median_s: f64,
    /// Samples whose first NMPC attempt failed.
    pub failed_first_attempts: usize,
    /// Samples solved by the relaxed retry (sub-relaxation + LM).
    pub relaxed_samples: usize,
    /// Samples where the linear MPC plan was applied after NMPC failure.
    pub fallback_samples: usize,
    /// Samples on the linear MPC plan within `ControllerSettings::fallback_hold` samples of a
    /// fallback (NMPC not tried).
    pub held_samples: usize,
    /// Samples where at least one NMPC plan was rejected for leaving the model's range
    /// (`ControllerSettings::plan_joint_limit_deg`).
    pub joint_limit_samples: usize,
    /// Largest joint angle between links predicted by any applied plan (deg; 0 without a
    /// joint monitor).
    pub max_plan_joint_angle_deg: f64,
    /// Time reached (s): the duration, or where the run stopped.
    pub t_end: f64,
    /// Why the run stopped early (plant failure), if it did.
    pub error: Option<String>,
}

/// Everything one closed loop produced.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    /// Summary metrics.
    pub summary: RunSummary,
    /// Joint names (columns of `joint_angles`).
    pub joint_names: Vec<String>,
    /// Input names (columns of `u`).
    pub input_names: Vec<String>,
    /// Time series.
    pub records: Vec<Record>,
    /// Per-sample solver reports.
    pub samples: Vec<SampleReport>,
    /// Snapshots every `snapshot_interval`.
    pub snapshots: Vec<Snapshot>,
    /// Wall time of the whole loop, plant included (s).
    pub wall_time_s: f64,
}

impl RunResult {
    /// A copy with every wall-clock timing and work count zeroed (for reproducibility
    /// checks: two runs of the same scenario are identical apart from timings; the work
    /// counts of a parallel line-search trial that fails depend on the threads' timing).
    pub fn without_timings(&self) -> Self {
        let mut r = self.clone();
        r.wall_time_s = 0.0;
        r.summary.solve_time_worst_s = 0.0;
        r.summary.solve_time_median_s = 0.0;
        r.summary.solve_threads = 0;
        r.summary.solve_cpu_per_thread_worst_s = 0.0;
        r.summary.solve_cpu_per_thread_median_s = 0.0;
        r.summary.solve_wall_worst_s = 0.0;
        r.summary.solve_wall_median_s = 0.0;
        for s in &mut r.samples {
            s.solve_time = 0.0;
            s.timing = SolveTiming::default();
            s.evaluations = Default::default();
        }
        r
    }

    /// Folds a repetition of the same closed loop into this one: each sample keeps the
    /// smallest of the two measurements of every solve time (thread CPU, all threads' CPU per
    /// thread, wall), and the summary's worst and median follow. The work of a sample is the
    /// same in every repetition, so its smallest time is the best estimate of that work's cost
    /// on the machine, with the interference of other processes filtered out.
    ///
    /// `Err` naming the first difference when `other` is not the same loop apart from its
    /// timings (a loop that is not reproducible, or another scenario).
    pub fn keep_fastest(&mut self, other: &RunResult) -> Result<()> {
        let (a, b) = (self.without_timings(), other.without_timings());
        if a != b {
            let what = if a.summary != b.summary {
                "summary".to_string()
            } else if let Some(k) = (0..a.samples.len().max(b.samples.len()))
                .find(|&k| a.samples.get(k) != b.samples.get(k))
            {
                format!("sample {k}")
            } else {
                "time series".to_string()
            };
            return Err(invalid(
                "repeated closed loop",
                what,
                "differs from the first run apart from its timings (the loop must be reproducible)",
            ));
        }
        self.wall_time_s = self.wall_time_s.min(other.wall_time_s);
        for (s, o) in self.samples.iter_mut().zip(&other.samples) {
            s.solve_time = s.solve_time.min(o.solve_time);
            s.timing.solve_cpu_all_threads =
                s.timing.solve_cpu_all_threads.min(o.timing.solve_cpu_all_threads);
            s.timing.solve_cpu_per_thread =
                s.timing.solve_cpu_per_thread.min(o.timing.solve_cpu_per_thread);
            s.timing.solve_wall_time = s.timing.solve_wall_time.min(o.timing.solve_wall_time);
        }
        let sm = &mut self.summary;
        [
            (sm.solve_time_worst_s, sm.solve_time_median_s),
            (sm.solve_cpu_per_thread_worst_s, sm.solve_cpu_per_thread_median_s),
            (sm.solve_wall_worst_s, sm.solve_wall_median_s),
        ] = solve_time_stats(&self.samples);
        Ok(())
    }
}

/// A plan in force: the start time of its first control interval and its controls.
struct Plan {
    start: f64,
    pieces: Vec<Vec<f64>>,
}

impl Plan {
    /// The control of the piece that covers time `t` (clamped to the plan).
    fn piece(&self, t: f64, dt: f64) -> &[f64] {
        let k = ((t - self.start) / dt + 1e-9).floor().max(0.0) as usize;
        &self.pieces[k.min(self.pieces.len() - 1)]
    }
}

/// Observation of the plant in modal and physical terms.
struct Observation {
    q: Vec<f64>,
    joint_angles: Vec<f64>,
    tip: [f64; 3],
    energy: f64,
    command_errors: Vec<f64>,
}

impl Observation {
    /// The record at time `t`, with the control `u` held from there and the state part of the
    /// cost under `weights`.
    fn record(self, t: f64, u: &[f64], weights: &Weights) -> Record {
        Record {
            t,
            v_state: weights.state_cost(&self.q),
            u: u.to_vec(),
            joint_angles: self.joint_angles,
            tip: self.tip,
            energy: self.energy,
            command_errors: self.command_errors,
            q: self.q,
        }
    }
}

fn observe(
    setup: &Setup,
    plant: &SimPlant,
    with_positions: bool,
    t: f64,
) -> Result<(Observation, Option<Snapshot>)> {
    let (mut obs, pos, xi) = observe_plant(setup, plant, with_positions)?;
    obs.command_errors = crate::reference::command_errors(
        &setup.scenario.references,
        &setup.joint_names,
        &setup.joint_nodes,
        &setup.reference_xi,
        &xi,
        t,
    );
    Ok((obs, pos))
}

/// [`observe`] without the command errors, and the node quaternions (global node order).
fn observe_plant(
    setup: &Setup,
    plant: &SimPlant,
    with_positions: bool,
) -> Result<(Observation, Option<Snapshot>, Vec<Vector4<f64>>)> {
    match plant {
        SimPlant::Fe { plant, .. } => {
            let nodes: Vec<Vector4<f64>> =
                plant.kinematics().iter().flat_map(|k| k.xi.iter().copied()).collect();
            let xi: Vec<[f64; 4]> = nodes.iter().map(|v| [v[0], v[1], v[2], v[3]]).collect();
            let q = setup.rom.project_full(plant.state(), Some(&xi))?;
            let nb = plant.structure().beams().len();
            let kin = plant.kinematics();
            let last = kin[nb - 1].r[kin[nb - 1].r.len() - 1];
            let pos =
                with_positions.then(|| snapshot_of(plant.time(), kin, plant.state().to_vec()));
            Ok((
                Observation {
                    q,
                    joint_angles: plant.joint_angles().to_vec(),
                    tip: [last.x, last.y, last.z],
                    energy: plant.energy(),
                    command_errors: Vec::new(),
                },
                pos,
                nodes,
            ))
        }
        SimPlant::Exact(p) => {
            let (x, kin) =
                p.configuration(&setup.scenario.structure, &setup.model.layout, setup.root_joint)?;
            let xi: Vec<Vector4<f64>> = kin.iter().flat_map(|k| k.xi.iter().copied()).collect();
            let xi4: Vec<[f64; 4]> = xi.iter().map(|v| [v[0], v[1], v[2], v[3]]).collect();
            let q = setup.rom.project_full(&x, Some(&xi4))?;
            let tip = kin.last().and_then(|k| k.r.last()).map_or([0.0; 3], |r| [r.x, r.y, r.z]);
            let pos = with_positions.then(|| snapshot_of(0.0, &kin, x.clone()));
            let obs = Observation {
                q,
                joint_angles: node_joint_angles(setup, &xi),
                tip,
                energy: p.rom.energy(&p.x),
                command_errors: Vec::new(),
            };
            Ok((obs, pos, xi))
        }
        SimPlant::Rom { q, .. } => {
            let fields = setup.rom.reconstruct(q)?;
            let xi: Vec<Vector4<f64>> = fields
                .xi
                .as_ref()
                .map(|v| v.iter().map(|a| Vector4::from_column_slice(a)).collect())
                .unwrap_or_else(|| setup.reference_xi.clone());
            let angles = node_joint_angles(setup, &xi);
            let positions = setup.rom.positions(q)?;
            let lb = positions.last().and_then(|b| b.last()).copied().unwrap_or([0.0; 3]);
            let snapshot = if with_positions {
                let mut flat = xi.iter().map(|v| [v[0], v[1], v[2], v[3]]);
                let orientations =
                    positions.iter().map(|b| flat.by_ref().take(b.len()).collect()).collect();
                let state = setup.rom.reconstruct_full(q)?;
                Some(Snapshot { t: 0.0, positions, orientations, state })
            } else {
                None
            };
            let obs = Observation {
                q: q.clone(),
                joint_angles: angles,
                tip: lb,
                energy: setup.rom.energy(q),
                command_errors: Vec::new(),
            };
            Ok((obs, snapshot, xi))
        }
    }
}

/// A snapshot of an FE configuration: node positions and quaternions per beam, and `state`.
fn snapshot_of(t: f64, kin: &[Kinematics], state: Vec<f64>) -> Snapshot {
    Snapshot {
        t,
        positions: kin.iter().map(|k| k.r.iter().map(|r| [r.x, r.y, r.z]).collect()).collect(),
        orientations: kin
            .iter()
            .map(|k| k.xi.iter().map(|v| [v[0], v[1], v[2], v[3]]).collect())
            .collect(),
        state,
    }
}

/// Joint angles (structure order) from the node quaternions `xi` (global node order):
/// supports relative to their reference, joints between links relative to their reference
/// relative rotation; signed for planar structures.
fn node_joint_angles(setup: &Setup, xi: &[Vector4<f64>]) -> Vec<f64> {
    setup
        .joint_nodes
        .iter()
        .map(|nodes| {
            if nodes.len() == 1 {
                let n = nodes[0];
                relative_angle(&setup.reference_xi[n], &xi[n], setup.planar_axis)
            } else {
                let (a, b) = (nodes[0], nodes[1]);
                let rel = relative_angle(&xi[a], &xi[b], setup.planar_axis);
                let rel0 = relative_angle(
                    &setup.reference_xi[a],
                    &setup.reference_xi[b],
                    setup.planar_axis,
                );
                rel - rel0
            }
        })
        .collect()
}

/// Runs one closed loop of `setup`'s scenario with disturbance magnitude `omega0`.
///
/// A plant failure (e.g. Newton divergence of the FE step, or a diverging ROM plant) or a
/// controller failure that leaves no plan (non-finite model evaluations) does not return
/// `Err`: the run stops there and the summary says so (`error`, `stabilised = false`). With
/// [`ControlGrid::Absolute`], a prediction to the grid that diverges is replaced by a plan
/// from the measured state at the sample itself.
pub fn run(
    setup: &Setup,
    omega0: f64,
    controller: &ControllerSettings,
    plant_kind: PlantKind,
) -> Result<RunResult> {
    if !omega0.is_finite() {
        return Err(invalid("omega0", omega0, "must be finite"));
    }
    let start = Instant::now();
    let sc = &setup.scenario;
    // checked in this order before any work (`drive` reads the same ratios)
    ratio("output_interval per sampling", sc.mpc.timing.sampling, sc.output_interval)?;
    ratio("output_interval per duration", sc.duration, sc.output_interval)?;
    let steps = ratio("plant.dt per output_interval", sc.output_interval, sc.plant.dt)?;
    ratio("output_interval per snapshot", sc.snapshot_interval, sc.output_interval)?;
    let x0 = sc.disturbed_state(omega0);
    let mut plant = SimPlant::fe(&sc.structure, sc.plant, steps, &sc.inputs, &x0)?;
    if plant_kind == PlantKind::Rom && controller.model == ModelKind::Paper {
        let (obs, _) = observe(setup, &plant, false, 0.0)?;
        plant = SimPlant::rom(&setup.rom, obs.q, sc.output_interval, sc.rom_plant_substeps)?;
    }
    match controller.model {
        ModelKind::Paper => {
            if let Some(c) = sc.references.first() {
                return Err(invalid(
                    "references",
                    &c.joint,
                    "the paper model cannot follow joint commands (its modes and joint rows are \
                     linearised at the reference angle); use model = exact-joints",
                ));
            }
            let mut ctrl = Controller::new(
                RomDynamics::new(&setup.rom)?,
                &setup.weights,
                &sc.mpc,
                controller,
            )?;
            ctrl.set_joint_monitor(JointMonitor::new(setup)?);
            drive(setup, omega0, controller, plant_kind, plant, ctrl, start, |_, obs| {
                Ok(obs.q.clone())
            })
        }
        ModelKind::ExactJoints => {
            let elastic = controller
                .link_elastic_modes
                .unwrap_or_else(|| default_link_elastic_modes(setup.planar_axis.is_none()));
            let (dynamics, weights) = ExactDynamics::for_setup(setup, elastic)?;
            let rom = dynamics.rom().clone();
            if plant_kind == PlantKind::Rom {
                // the exact-joints model itself as plant, from the projected initial state
                let x0 = match &plant {
                    SimPlant::Fe { plant, .. } => {
                        rom.project_fe(plant.state(), plant.kinematics())?
                    }
                    _ => return Err(invalid("plant", "rom", "starts from the FE state")),
                };
                plant = SimPlant::Exact(Box::new(ExactPlant::new(
                    rom.clone(),
                    x0,
                    sc.output_interval,
                    sc.rom_plant_substeps,
                )?));
            }
            let schedule = dynamics.reference_schedule(setup, &weights)?;
            let mut ctrl = Controller::new(dynamics, &weights, &sc.mpc, controller)?;
            if !sc.references.is_empty() {
                ctrl.set_reference_schedule(schedule)?;
            }
            // state feedback: the FE plant state projected onto the exact-joints state
            // (theory.md §10)
            drive(setup, omega0, controller, plant_kind, plant, ctrl, start, move |p, _| match p {
                SimPlant::Fe { plant, .. } => {
                    Ok(rom.project_fe(plant.state(), plant.kinematics())?)
                }
                SimPlant::Exact(p) => Ok(p.x.clone()),
                SimPlant::Rom { .. } => Err(invalid("plant", "rom", "not the exact-joints model")),
            })
        }
    }
}

/// The sampling loop of [`run`] with the controller `ctrl` on its model `D`; `measure` maps
/// the plant and its observation to the controller's state.
#[allow(clippy::too_many_arguments)]
fn drive<D: ocp_transcription::Dynamics + Clone>(
    setup: &Setup,
    omega0: f64,
    controller: &ControllerSettings,
    plant_kind: PlantKind,
    mut plant: SimPlant,
    mut ctrl: Controller<D>,
    start: Instant,
    measure: impl Fn(&SimPlant, &Observation) -> Result<Vec<f64>>,
) -> Result<RunResult> {
    let sc = &setup.scenario;
    let per_sample =
        ratio("output_interval per sampling", sc.mpc.timing.sampling, sc.output_interval)?;
    let n_out = ratio("output_interval per duration", sc.duration, sc.output_interval)?;
    let per_snap = ratio("output_interval per snapshot", sc.snapshot_interval, sc.output_interval)?;
    let nu = sc.inputs.len();
    let mut u = vec![0.0; nu];
    let anchored = sc.mpc.control_grid == ControlGrid::Absolute;
    let dt_plan = ctrl.interval();
    // the plan in force (start time, pieces) and the one before it (still in force until the
    // new plan's start when that lies after the sample)
    let mut plan: Option<Plan> = None;
    let mut previous: Option<Plan> = None;
    let mut records = Vec::with_capacity(n_out + 1);
    let mut samples = Vec::new();
    let mut snapshots = Vec::new();
    let mut error = None;
    for k in 0..=n_out {
        let t = k as f64 * sc.output_interval;
        let (obs, pos) = observe(setup, &plant, k % per_snap == 0, t)?;
        if let Some(s) = pos {
            snapshots.push(Snapshot { t, ..s });
        }
        if k < n_out && k % per_sample == 0 {
            let x = measure(&plant, &obs)?;
            let rep = match (&plan, anchored) {
                (Some(p), true) => {
                    // next time on the absolute grid kΔt (t itself when on it)
                    let g = ((t / dt_plan - 1e-9).ceil() * dt_plan).max(t);
                    match ctrl.predict(&x, p.piece(t, dt_plan), g - t) {
                        Ok(xp) => ctrl.step_from(t, g, &xp),
                        // the model diverges from the measured state (far outside its range):
                        // plan from the measurement itself, starting at the sample
                        Err(_) => ctrl.step(t, &x),
                    }
                }
                _ => ctrl.step(t, &x),
            };
            let rep = match rep {
                Ok(r) => r,
                Err(e) => {
                    // a solver failure that leaves no plan (e.g. non-finite model evaluations
                    // from a state far outside the model's range) stops the run like a plant
                    // failure does
                    error = Some(format!("controller at t = {t}: {e}"));
                    records.push(obs.record(t, &u, &setup.weights));
                    break;
                }
            };
            let mut pieces: Vec<Vec<f64>> =
                ctrl.plan().1.iter().map(|c| c.iter().copied().collect()).collect();
            if let Some(first) = pieces.first_mut() {
                first.copy_from_slice(&rep.u);
            }
            previous = plan.take();
            plan = Some(Plan { start: rep.plan_start, pieces });
            samples.push(rep);
        }
        if let Some(p) = &plan {
            let active = match &previous {
                Some(q) if t < p.start - 1e-9 => q,
                _ => p,
            };
            u.copy_from_slice(active.piece(t, dt_plan));
        }
        records.push(obs.record(t, &u, &setup.weights));
        if k == n_out {
            break;
        }
        if let Err(e) = plant.advance(&u) {
            error = Some(e.to_string());
            break;
        }
    }
    let mut summary =
        summarise(setup, omega0, controller.kind, plant_kind, &records, &samples, error);
    summary.model = controller.model.name().into();
    Ok(RunResult {
        summary,
        joint_names: setup.joint_names.clone(),
        input_names: sc.inputs.iter().map(|i| i.name().to_string()).collect(),
        records,
        samples,
        snapshots,
        wall_time_s: start.elapsed().as_secs_f64(),
    })
}

/// Runs the plant open loop from the scenario's initial state at `omega0` with the given
/// control per output interval (`inputs[k]` held on `[k, k+1)·output_interval`; the run
/// lasts `inputs.len()` intervals) and records it like [`run`] does (for model validation:
/// replay one input history on the FE plant and on the modal model and compare).
pub fn open_loop(
    setup: &Setup,
    omega0: f64,
    inputs: &[Vec<f64>],
    plant_kind: PlantKind,
) -> Result<Vec<Record>> {
    if !omega0.is_finite() {
        return Err(invalid("omega0", omega0, "must be finite"));
    }
    let sc = &setup.scenario;
    let nu = sc.inputs.len();
    if let Some((k, u)) = inputs.iter().enumerate().find(|(_, u)| u.len() != nu) {
        return Err(invalid(format!("inputs[{k}] length"), u.len(), format!("must be {nu}")));
    }
    let steps = ratio("plant.dt per output_interval", sc.output_interval, sc.plant.dt)?;
    let x0 = sc.disturbed_state(omega0);
    let mut plant = SimPlant::fe(&sc.structure, sc.plant, steps, &sc.inputs, &x0)?;
    if plant_kind == PlantKind::Rom {
        let (obs, _) = observe(setup, &plant, false, 0.0)?;
        plant = SimPlant::rom(&setup.rom, obs.q, sc.output_interval, sc.rom_plant_substeps)?;
    }
    let mut records = Vec::with_capacity(inputs.len() + 1);
    for k in 0..=inputs.len() {
        let (obs, _) = observe(setup, &plant, false, k as f64 * sc.output_interval)?;
        let u = inputs.get(k).cloned().unwrap_or_else(|| vec![0.0; nu]);
        records.push(obs.record(k as f64 * sc.output_interval, &u, &setup.weights));
        if k < inputs.len() {
            plant.advance(&u)?;
        }
    }
    Ok(records)
}

/// Largest and median of `times` (0 for none).
fn worst_median(times: impl Iterator<Item = f64>) -> (f64, f64) {
    let mut times: Vec<f64> = times.collect();
    times.sort_by(|a, b| a.total_cmp(b));
    let median = if times.is_empty() {
        0.0
    } else if times.len() % 2 == 1 {
        times[times.len() / 2]
    } else {
        0.5 * (times[times.len() / 2 - 1] + times[times.len() / 2])
    };
    (times.last().copied().unwrap_or(0.0), median)
}

/// Worst and median per-sample solve time in each measure: the calling thread's CPU, the CPU
/// per thread, the wall clock.
fn solve_time_stats(samples: &[SampleReport]) -> [(f64, f64); 3] {
    [
        worst_median(samples.iter().map(|s| s.solve_time)),
        worst_median(samples.iter().map(|s| s.timing.solve_cpu_per_thread)),
        worst_median(samples.iter().map(|s| s.timing.solve_wall_time)),
    ]
}

fn summarise(
    setup: &Setup,
    omega0: f64,
    kind: ControllerKind,
    plant: PlantKind,
    records: &[Record],
    samples: &[SampleReport],
    error: Option<String>,
) -> RunSummary {
    let first = &records[0];
    let last = &records[records.len() - 1];
    let nr = setup.rom.n_rigid();
    let rigid = |q: &[f64]| q[..nr].iter().map(|v| v * v).sum::<f64>().sqrt();
    let rigid_rate_ratio = rigid(&last.q) / rigid(&first.q);
    let v_ratio_final = last.v_state / first.v_state;
    let links: Vec<usize> = setup
        .joint_nodes
        .iter()
        .enumerate()
        .filter(|(_, n)| n.len() == 2)
        .map(|(j, _)| j)
        .collect();
    let max_joint = records
        .iter()
        .flat_map(|r| links.iter().map(move |&j| r.joint_angles[j].abs()))
        .fold(0.0, f64::max);
    let root = setup.root_joint;
    let max_orient = records.iter().map(|r| r.joint_angles[root].abs()).fold(0.0, f64::max);
    let orient = last.joint_angles[root].abs();
    let [(worst, median), (per_thread_worst, per_thread_median), (wall_worst, wall_median)] =
        solve_time_stats(samples);
    let completed = error.is_none();
    let peak = records.iter().map(|r| r.energy).fold(0.0, f64::max);
    let energy_ratio_final = if peak > 0.0 { last.energy / peak } else { 0.0 };
    let command_errors_deg: Vec<f64> = last.command_errors.iter().map(|e| e.to_degrees()).collect();
    let stabilised = completed
        && if command_errors_deg.is_empty() {
            rigid_rate_ratio < 0.05 && orient <= 0.2 * max_orient && v_ratio_final < 0.1
        } else {
            command_errors_deg.iter().all(|e| *e <= COMMAND_TOLERANCE_DEG)
                && energy_ratio_final < ENERGY_RATIO_LIMIT
        };
    RunSummary {
        omega0,
        controller: kind.name().into(),
        plant: plant.name().into(),
        model: ModelKind::Paper.name().into(),
        v_ratio_final,
        max_joint_angle_deg: max_joint.to_degrees(),
        orientation_error_deg: orient.to_degrees(),
        max_orientation_deg: max_orient.to_degrees(),
        rigid_rate_ratio,
        stabilised,
        energy_ratio_final,
        command_errors_deg,
        solve_time_worst_s: worst,
        solve_time_median_s: median,
        solve_threads: samples.iter().map(|s| s.timing.solve_threads).max().unwrap_or(1),
        solve_cpu_per_thread_worst_s: per_thread_worst,
        solve_cpu_per_thread_median_s: per_thread_median,
        solve_wall_worst_s: wall_worst,
        solve_wall_median_s: wall_median,
        failed_first_attempts: samples
            .iter()
            .filter(|s| matches!(s.strategy, Strategy::Relaxed | Strategy::Fallback))
            .count(),
        relaxed_samples: samples.iter().filter(|s| s.strategy == Strategy::Relaxed).count(),
        fallback_samples: samples.iter().filter(|s| s.strategy == Strategy::Fallback).count(),
        held_samples: samples.iter().filter(|s| s.strategy == Strategy::Held).count(),
        joint_limit_samples: samples.iter().filter(|s| s.joint_limit_rejections > 0).count(),
        max_plan_joint_angle_deg: samples
            .iter()
            .filter_map(|s| s.plan_joint_angle_deg)
            .fold(0.0, f64::max),
        t_end: last.t,
        error,
    }
}

/// Runs `omegas` in parallel (rayon), results in the order of `omegas`; `progress` is called
/// once per finished run (e.g. to advance a progress bar).
pub fn sweep(
    setup: &Setup,
    omegas: &[f64],
    controller: &ControllerSettings,
    plant: PlantKind,
    progress: &(dyn Fn() + Sync),
) -> Vec<Result<RunResult>> {
    omegas
        .par_iter()
        .map(|&w| {
            let r = run(setup, w, controller, plant);
            progress();
            r
        })
        .collect()
}
