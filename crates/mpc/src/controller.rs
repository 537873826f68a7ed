//! Controllers: nonlinear MPC (SQP on the augmented modal model) and linear MPC (one QP per
//! sample on the model linearised at the reference), paper §4.

use crate::dynamics::RomDynamics;
use crate::error::{invalid, Result};
use crate::exact_dynamics::ModelKind;
use crate::reference::ReferenceSchedule;
use crate::validity::JointMonitor;
use crate::weights::{MpcSettings, Weights};
use nalgebra::DVector;
use ocp_transcription::{
    Dynamics, Globalisation, HessianApproximation, Integrator, IntegratorKind, IntegratorSettings,
    QpForm, SqpMode, SqpSettings, SqpSolver, SqpStatus, TailSubsteps,
};
use serde::{Deserialize, Serialize};
use std::time::Instant;

mod first_sample;
mod report;
pub use first_sample::InitialGuess;
pub use report::{SampleReport, SolveTiming, Strategy};

/// Newton tolerance of the implicit midpoint rule in the real-time exact-joints controller
/// ([`ControllerSettings::exact_joints`]), on the relative residual `‖r‖∞ / (1 + ‖m‖∞)`.
pub const REAL_TIME_NEWTON_TOLERANCE: f64 = 1e-8;

/// Which controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ControllerKind {
    /// Nonlinear MPC: SQP on the augmented modal model (29).
    Nmpc,
    /// Linear MPC: the same problem on (29) linearised at the reference, one QP per sample.
    Lmpc,
}

impl ControllerKind {
    /// `"nmpc"` or `"lmpc"`.
    pub fn name(self) -> &'static str {
        match self {
            ControllerKind::Nmpc => "nmpc",
            ControllerKind::Lmpc => "lmpc",
        }
    }
}

/// Default of [`ControllerSettings::plan_joint_limit_deg`] (deg).
pub const DEFAULT_PLAN_JOINT_LIMIT: Option<f64> = Some(20.0);

/// Default of [`ControllerSettings::fallback_hold`] (samples).
pub const DEFAULT_FALLBACK_HOLD: usize = 5;

/// Settings of the controllers' solvers. Defaults ([`Default`]: the real-time NMPC) in
/// brackets; [`ControllerSettings::full_sqp`] is the full SQP.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerSettings {
    /// Which controller \[NMPC\].
    pub kind: ControllerKind,
    /// Integrator inside each shooting interval [Lawson RK4 on `W`, 16 substeps per
    /// `Δt = 0.25 s`; its one-interval error: theory.md §8].
    pub integrator: IntegratorSettings,
    /// Real-time iteration: one SQP iteration (one QP) per sample from the shifted plan,
    /// instead of iterating to the KKT tolerance \[true; false in
    /// [`ControllerSettings::full_sqp`]\]. The retry and fallback still apply when that
    /// iteration fails. One QP per sample bounds the time per sample; converging each
    /// sample's problem follows fast motion more closely (the trade-off is measured in
    /// docs/mpc.md, "Real time").
    pub real_time_iteration: bool,
    /// SQP iteration limit of the NMPC per sample \[10\].
    pub max_iterations: usize,
    /// Full SQP only: the first sample first runs up to this many SQP iterations from its
    /// initial guess ([`Self::first_sample_guess`]; there is no shifted converged plan yet),
    /// then its ordinary solve (up to [`Self::max_iterations`] more) from where they ended.
    /// Both count in the first sample's iterations and solve time. When the dynamics are not
    /// finite along the guess (no iteration possible), these iterations start from the
    /// guess's controls rolled out from the measured state instead
    /// ([`SqpSolver::solve_with_fallback_starts`]). `None`: the first sample is solved like
    /// the others \[None\].
    pub first_sample_iterations: Option<usize>,
    /// Initial guess of the first sample's NMPC solve \[the linear MPC plan\].
    pub first_sample_guess: InitialGuess,
    /// Full SQP with [`Self::first_sample_iterations`] only: continuation (homotopy) in the
    /// initial state for the first sample. With `m` steps, the first sample's iterations run
    /// `m` times, for the initial states `x0(α_j) = x_r + α_j (x0 − x_r)`, `α_j = j/m`
    /// (`j = 1…m`, `α_m = 1`: the measured state), each from where the previous one ended;
    /// the initial guess ([`Self::first_sample_guess`]) is built for `x0(α_1)`. A smaller
    /// disturbance is closer to the reference, where the guess is good and the SQP converges,
    /// and each solution is a start near the next one (first_sample::continuation_states).
    /// Each step runs up to [`Self::first_sample_iterations`] iterations, all counted in the
    /// first sample. `1`: no continuation \[1\].
    pub first_sample_continuation: usize,
    /// Full SQP with [`Self::first_sample_iterations`] only: Levenberg–Marquardt term of the
    /// first sample's extra iterations (and its continuation steps); `None`: that of the
    /// first attempt, [`Self::levenberg_marquardt`] \[None\].
    pub first_sample_levenberg_marquardt: Option<f64>,
    /// Warm start of the later samples: after the shift, the first `rollout_intervals` nodes
    /// of the plan are re-simulated from the measured state with the plan's controls
    /// ([`SqpSolver::roll_out`]), so the solve starts with zero defects there instead of
    /// the jump between the measured state and the shifted plan's first node (the plant's
    /// motion the model did not predict). When the rollout is not finite, the shifted plan
    /// is kept. Values above the horizon's interval count re-simulate the whole plan. `0`: the
    /// shifted plan as it is \[0\].
    pub rollout_intervals: usize,
    /// KKT tolerance of the NMPC (max-norm natural residual; the inputs are O(0.1–5), so
    /// 1e-4 resolves them to far below what the plant feels within `τs`) [1e-4].
    pub kkt_tolerance: f64,
    /// An attempt that ends at the iteration limit is accepted only when its constraint
    /// violation (shooting defects, max norm) is at most this, i.e. its plan is a consistent
    /// trajectory of the model; otherwise the retry / fallback follow [1e-2]. (Requiring a
    /// small KKT residual too rejected every 3D sample at 10 iterations although those plans
    /// control the structure well.)
    pub accept_violation: f64,
    /// Levenberg–Marquardt term of the first attempt \[0\]. 1e-2 helped the 2D sweep at
    /// ω0 = 1.75–2.0 but stalled every 3D sample (no plan accepted, LMPC fallback throughout),
    /// so it is an option, not the default.
    pub levenberg_marquardt: f64,
    /// Globalisation of the first attempt [merit line search].
    pub globalisation: Globalisation,
    /// QP form [condensed, dense interior point].
    pub qp_form: QpForm,
    /// When the first attempt fails: retry from the linear MPC plan with the paper's fixed
    /// sub-relaxation `α` and a Levenberg–Marquardt term ([`Self::retry_levenberg_marquardt`])
    /// \[None; Some(0.5) in [`ControllerSettings::full_sqp`]\]; `None`: no retry.
    pub retry_relaxation: Option<f64>,
    /// Levenberg–Marquardt term of the retry [1e-3].
    pub retry_levenberg_marquardt: f64,
    /// When every NMPC attempt fails, apply the linear MPC plan [true]; `false`: apply the
    /// NMPC's own last (unconverged) iterate and warm-start the next sample from it.
    pub fallback_to_lmpc: bool,
    /// Range of validity of the controller model: an NMPC plan (first attempt or relaxed
    /// retry) whose predicted joint angle between links exceeds this (deg) at any of its
    /// nodes is treated as a failed attempt (→ relaxed retry → linear MPC fallback), like a
    /// solver failure. Needs the joint geometry ([`Controller::set_joint_monitor`]; the closed
    /// loop sets it); `None`: no check. [20°: the paper model's modes are linearised at the
    /// reference angle, and beyond about 20° its plans stop describing the structure; the
    /// measured choice is in docs/mpc.md, "Why the joint-angle limit and the hold"]
    pub plan_joint_limit_deg: Option<f64>,
    /// After a fallback to the linear MPC plan, the next `fallback_hold` samples apply the
    /// linear MPC plan directly (strategy [`Strategy::Held`]) before the NMPC is tried again:
    /// a failure or an out-of-range plan means the state is where the model is not trusted,
    /// and switching back and forth between the two controllers' plans every sample excites
    /// the structure [5 samples = 1 s; the measured choice is in docs/mpc.md, "Why the
    /// joint-angle limit and the hold"].
    pub fallback_hold: usize,
    /// The controller's reduced model \[paper\]: the paper's (29), or the exact-joints model
    /// (theory.md §10, [`crate::ExactDynamics`]) with the basis of [`Self::link_elastic_modes`].
    /// The exact-joints model is controlled by the NMPC only, without the joint-angle check
    /// (the check reads the paper model's state): `kind = lmpc` or `plan_joint_limit_deg`
    /// with it is an error.
    pub model: ModelKind,
    /// Exact-joints model only: per-link basis of the rigid link motions plus this many
    /// elastic modes (the lowest constrained modes at the reference, split per link);
    /// `None`: 4 for planar, 16 for spatial structures (docs/exact-joints-results.md) \[None\].
    pub link_elastic_modes: Option<usize>,
    /// Integrate the NMPC's shooting intervals on the rayon thread pool
    /// ([`ocp_transcription::SqpSettings::parallel_intervals`]: the linearisation's
    /// sensitivity sweeps and the line search's trial passes, for the first attempt and the
    /// relaxed retry; condensing, the QP and the linear MPC stay on the calling thread)
    /// \[false\]. Every value is valid, and the result does not depend on it: each interval is
    /// integrated alone and the sums over intervals run in interval order, so the plans and
    /// the closed loop are the same bits for any pool size, on or off. It shortens a sample's
    /// wall time on more than one core; its CPU time is then spread over the pool
    /// ([`SolveTiming::solve_cpu_per_thread`]).
    pub parallel_intervals: bool,
}

/// The default is the real-time NMPC ([`ControllerSettings::real_time`] with merit line
/// search): one SQP iteration per sample, no relaxed retry. It meets the paper's sampling time
/// `τs = 0.2 s` with a wide margin (FE plant, one core, docs/mpc.md "Real time": worst sample
/// 5–20 ms in 2D, 29–37 ms in 3D), where the full SQP ([`ControllerSettings::full_sqp`])
/// takes up to 0.2 s in 2D and 0.76 s in 3D. Merit line search, because full steps diverge in
/// 3D at ω0 = 0.75; in 2D full steps keep more ω0 (`scenes/paper-2d-mpc.toml` sets
/// `line_search = false`).
impl Default for ControllerSettings {
    fn default() -> Self {
        Self::real_time(true)
    }
}

impl ControllerSettings {
    /// Defaults with the given kind.
    pub fn of(kind: ControllerKind) -> Self {
        Self { kind, ..Self::default() }
    }

    /// The full SQP NMPC: up to 10 SQP iterations per sample to the KKT tolerance 1e-4, merit
    /// line search, the paper's relaxed retry from the linear MPC plan, then the linear MPC
    /// fallback. The most robust setting, not real time (worst samples 16–196 ms in 2D,
    /// 0.24–0.76 s in 3D; docs/mpc.md).
    pub fn full_sqp() -> Self {
        Self {
            kind: ControllerKind::Nmpc,
            integrator: IntegratorSettings::new(IntegratorKind::LawsonRk4, 16),
            real_time_iteration: false,
            max_iterations: 10,
            first_sample_iterations: None,
            first_sample_guess: InitialGuess::LinearMpc,
            first_sample_continuation: 1,
            first_sample_levenberg_marquardt: None,
            rollout_intervals: 0,
            kkt_tolerance: 1e-4,
            accept_violation: 1e-2,
            levenberg_marquardt: 0.0,
            globalisation: Globalisation::merit(),
            qp_form: QpForm::Auto,
            retry_relaxation: Some(0.5),
            retry_levenberg_marquardt: 1e-3,
            fallback_to_lmpc: true,
            plan_joint_limit_deg: DEFAULT_PLAN_JOINT_LIMIT,
            fallback_hold: DEFAULT_FALLBACK_HOLD,
            model: ModelKind::Paper,
            link_elastic_modes: None,
            parallel_intervals: false,
        }
    }

    /// The real-time NMPC of the paper's scenes (`scenes/paper-{2d,3d}-mpc.toml`; docs/mpc.md,
    /// "Real time"): one SQP iteration per sample (RTI; held samples after a fallback spend
    /// one NMPC iteration each, not applied), no relaxed retry, and the first attempt's step
    /// a full Gauss–Newton step (`line_search = false`: the planar scenes) or merit line
    /// search (`true`: the spatial scenes, where full steps diverge at large motion). The
    /// range each one stabilises and its time per sample: docs/mpc.md, "Real time".
    pub fn real_time(line_search: bool) -> Self {
        Self {
            real_time_iteration: true,
            globalisation: if line_search {
                Globalisation::merit()
            } else {
                Globalisation::FullStep
            },
            retry_relaxation: None,
            ..Self::full_sqp()
        }
    }

    /// The real-time NMPC for spatial (3D) structures: [`Self::real_time`] with merit line
    /// search, and without the two safeguards that lean on the linear MPC — no joint-angle
    /// check of the plans and no fallback to the linear MPC plan (a failed iteration applies
    /// the NMPC's own iterate). In 3D the linear MPC itself fails from ω0 ≈ 0.75 (paper
    /// §5.3), so falling back to it hurts (measured range: docs/mpc.md, "3D NMPC up to
    /// ω0 = 1").
    pub fn real_time_spatial() -> Self {
        Self { plan_joint_limit_deg: None, fallback_to_lmpc: false, ..Self::real_time(true) }
    }

    /// The NMPC on the exact-joints model (theory.md §10, [`crate::ExactDynamics`]) of
    /// `scenes/paper-3d-mpc.toml`, real time: one SQP iteration per sample (RTI) with the merit
    /// line search and a Levenberg–Marquardt term 1e-3, without the relaxed retry, the linear
    /// MPC fallback and the plan joint-angle check (all three lean on the model linearised at
    /// the reference angle; a failed sample applies the NMPC's own iterate). Each later
    /// sample's warm start has its first two intervals re-simulated from the measured state
    /// ([`Self::rollout_intervals`] = 2): measured on the FE plant, ✓ at ω0 = 0.25…1.5 with
    /// it and 0.25…1.0 without (docs/mpc.md, "3D sweep"). The shooting
    /// intervals use the implicit midpoint rule with 4 substeps: Lawson RK4 takes its exact
    /// linear part at the reference angle, and with the joints bent the remainder carries
    /// elastic frequencies beyond the stability limit of its substeps; the implicit midpoint
    /// rule is A-stable, so its few substeps keep the fast elastic modes bounded (inaccurate,
    /// which the controller does not need). The horizon's second half (intervals 12–23 of the
    /// paper's 24) takes 2 substeps ([`IntegratorSettings::tail`]): only the first control is
    /// applied, and the far plan needs the slow motion, which the coarser steps keep to
    /// second order (about 40 % less work in the first samples and 20 % over a loop, and the
    /// stabilised ranges hold: docs/mpc.md, "Coarser substeps at the end of the horizon"; a
    /// horizon of 12 intervals or fewer needs its own `integrator.tail`, or `None`). Its
    /// Newton iterations stop at the relative residual 1e-8 ([`REAL_TIME_NEWTON_TOLERANCE`])
    /// instead of the library's 1e-13: the substeps' own error is orders of magnitude larger,
    /// and the defects and merit differences the iteration decides on are of order one (about
    /// 11 % less thread CPU per sample, the same stabilised ranges; 1e-6 lost the edges of
    /// both, docs/mpc.md).
    /// Stabilises the paper's 3D spin to ω0 = 1 on the FE plant within the sampling time; the
    /// full SQP (`real_time_iteration = false`, 16 substeps, no Levenberg–Marquardt term)
    /// reaches ω0 = 1.125 at seconds per sample
    /// (docs/mpc.md, "The exact-joints model in the closed loop", for the measured ranges and
    /// times).
    pub fn exact_joints() -> Self {
        Self {
            model: ModelKind::ExactJoints,
            integrator: IntegratorSettings {
                newton_tolerance: REAL_TIME_NEWTON_TOLERANCE,
                tail: Some(TailSubsteps { from_interval: 12, substeps: 2 }),
                ..IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 4)
            },
            levenberg_marquardt: 1e-3,
            retry_relaxation: None,
            fallback_to_lmpc: false,
            plan_joint_limit_deg: None,
            rollout_intervals: 2,
            ..Self::real_time(true)
        }
    }

    /// Checks the ranges (the solver settings are checked again by `ocp-transcription`).
    pub fn validate(&self) -> Result<()> {
        self.integrator.validate().map_err(|e| match e {
            ocp_transcription::OcpError::InvalidSetting { field, value, reason } => {
                invalid(field, value, reason)
            }
            e => e.into(),
        })?;
        if self.max_iterations == 0 {
            return Err(invalid("max_iterations", 0, "must be at least 1"));
        }
        if let Some(n) = self.first_sample_iterations {
            if n == 0 {
                return Err(invalid("first_sample_iterations", 0, "must be at least 1"));
            }
            if self.real_time_iteration {
                return Err(invalid(
                    "first_sample_iterations",
                    n,
                    "needs the full SQP (real_time_iteration = false)",
                ));
            }
        }
        if self.first_sample_continuation == 0 {
            return Err(invalid("first_sample_continuation", 0, "must be at least 1"));
        }
        if self.first_sample_continuation > 1 && self.first_sample_iterations.is_none() {
            return Err(invalid(
                "first_sample_continuation",
                self.first_sample_continuation,
                "needs first_sample_iterations",
            ));
        }
        if let Some(v) = self.first_sample_levenberg_marquardt {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(invalid(
                    "first_sample_levenberg_marquardt",
                    v,
                    "must be finite and ≥ 0",
                ));
            }
            if self.first_sample_iterations.is_none() {
                return Err(invalid(
                    "first_sample_levenberg_marquardt",
                    v,
                    "needs first_sample_iterations",
                ));
            }
        }
        if !(self.kkt_tolerance > 0.0 && self.kkt_tolerance.is_finite()) {
            return Err(invalid("kkt_tolerance", self.kkt_tolerance, "must be finite and > 0"));
        }
        if !(self.accept_violation > 0.0 && self.accept_violation.is_finite()) {
            return Err(invalid(
                "accept_violation",
                self.accept_violation,
                "must be finite and > 0",
            ));
        }
        for (name, v) in [
            ("levenberg_marquardt", self.levenberg_marquardt),
            ("retry_levenberg_marquardt", self.retry_levenberg_marquardt),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(invalid(name, v, "must be finite and ≥ 0"));
            }
        }
        if let Some(a) = self.retry_relaxation {
            if !(a > 0.0 && a <= 1.0) {
                return Err(invalid("retry_relaxation", a, "must be in (0, 1]"));
            }
        }
        if let Some(a) = self.plan_joint_limit_deg {
            if !(a > 0.0 && a <= 180.0) {
                return Err(invalid("plan_joint_limit_deg", a, "must be in (0, 180]"));
            }
        }
        // `parallel_intervals`: every value is valid (it does not change the result)
        if self.model == ModelKind::ExactJoints {
            if self.kind == ControllerKind::Lmpc {
                return Err(invalid(
                    "kind",
                    "lmpc",
                    "the exact-joints model is controlled by the NMPC only",
                ));
            }
            if let Some(a) = self.plan_joint_limit_deg {
                return Err(invalid(
                    "plan_joint_limit_deg",
                    a,
                    "must be none with model = exact-joints (the check reads the paper model's state)",
                ));
            }
        }
        Ok(())
    }
}

/// A receding-horizon controller on a reduced model `D`: the paper's augmented modal model
/// ([`RomDynamics`], the default) or the exact-joints model ([`crate::ExactDynamics`]).
pub struct Controller<D: Dynamics + Clone = RomDynamics> {
    settings: ControllerSettings,
    mpc: MpcSettings,
    nmpc: Option<SqpSolver<D>>,
    /// The first sample's solver ([`ControllerSettings::first_sample_iterations`]).
    initial: Option<SqpSolver<D>>,
    relaxed: Option<SqpSolver<D>>,
    lmpc: SqpSolver<D>,
    samples: usize,
    /// Samples left on the linear MPC after a fallback ([`ControllerSettings::fallback_hold`]).
    hold: usize,
    /// Start time of the last plan (for the warm-start shift).
    last_start: Option<f64>,
    /// The model used to predict a measured state to the plan's start: the nonlinear model
    /// (29) for both controllers (a linearised predictor made the 3D LMPC diverge at ω0 = 0.5).
    predictor: D,
    /// Joint angles of plans, for the validity check and the reports.
    monitor: Option<JointMonitor>,
    /// Time-dependent reference (joint commands); `None`: the weights' constant reference.
    schedule: Option<ReferenceSchedule>,
}

impl<D: Dynamics + Clone> std::fmt::Debug for Controller<D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Controller")
            .field("settings", &self.settings)
            .field("samples", &self.samples)
            .finish()
    }
}

fn status_name(s: SqpStatus) -> String {
    format!("{s:?}")
}

impl<D: Dynamics + Clone> Controller<D> {
    /// Builds the controller for `model` with the assembled `weights`.
    pub fn new(
        model: D,
        weights: &Weights,
        mpc: &MpcSettings,
        settings: &ControllerSettings,
    ) -> Result<Self> {
        mpc.validate()?;
        settings.validate()?;
        let nu = model.nu();
        let nx = model.nx();
        let ocp = weights.ocp(mpc, nx, nu)?;
        let base = SqpSettings {
            hessian: HessianApproximation::GaussNewton,
            qp_form: settings.qp_form,
            integrator: settings.integrator.clone(),
            kkt_tolerance: settings.kkt_tolerance,
            ..SqpSettings::default()
        };
        let lq = SqpSettings {
            mode: SqpMode::LinearQuadratic,
            globalisation: Globalisation::FullStep,
            max_iterations: 2,
            ..base.clone()
        };
        let lmpc = SqpSolver::new(model.clone(), ocp.clone(), lq)?;
        let predictor = model.clone();
        let (nmpc, initial, relaxed) = match settings.kind {
            ControllerKind::Lmpc => (None, None, None),
            ControllerKind::Nmpc => {
                let s = SqpSettings {
                    mode: if settings.real_time_iteration {
                        SqpMode::RealTimeIteration
                    } else {
                        SqpMode::Sqp
                    },
                    globalisation: settings.globalisation,
                    levenberg_marquardt: settings.levenberg_marquardt,
                    max_iterations: settings.max_iterations,
                    parallel_intervals: settings.parallel_intervals,
                    ..base
                };
                let relaxed = match settings.retry_relaxation {
                    Some(alpha) => {
                        let r = SqpSettings {
                            mode: SqpMode::Sqp,
                            globalisation: Globalisation::FixedRelaxation { alpha },
                            levenberg_marquardt: settings.retry_levenberg_marquardt,
                            // a fixed relaxation contracts by (1 − α) per iteration at best
                            max_iterations: 2 * settings.max_iterations,
                            ..s.clone()
                        };
                        Some(SqpSolver::new(model.clone(), ocp.clone(), r)?)
                    }
                    None => None,
                };
                let initial = match settings.first_sample_iterations {
                    Some(n) => {
                        let i = SqpSettings {
                            max_iterations: n,
                            levenberg_marquardt: settings
                                .first_sample_levenberg_marquardt
                                .unwrap_or(settings.levenberg_marquardt),
                            ..s.clone()
                        };
                        Some(SqpSolver::new(model.clone(), ocp.clone(), i)?)
                    }
                    None => None,
                };
                (Some(SqpSolver::new(model, ocp, s)?), initial, relaxed)
            }
        };
        Ok(Self {
            settings: settings.clone(),
            mpc: mpc.clone(),
            nmpc,
            initial,
            relaxed,
            lmpc,
            samples: 0,
            hold: 0,
            last_start: None,
            predictor,
            monitor: None,
            schedule: None,
        })
    }

    /// Gives the controller the joint geometry of its model, so that it reports each plan's
    /// predicted joint angles and applies [`ControllerSettings::plan_joint_limit_deg`]
    /// ([`crate::run`] does this).
    pub fn set_joint_monitor(&mut self, monitor: JointMonitor) {
        self.monitor = Some(monitor);
    }

    /// Makes the reference of every plan the schedule's states at the times of the plan's
    /// shooting nodes ([`crate::reference`]).
    pub fn set_reference_schedule(&mut self, schedule: ReferenceSchedule) -> Result<()> {
        let nx = self.predictor.nx();
        if schedule.at(0.0).len() != nx {
            return Err(invalid(
                "reference schedule",
                schedule.at(0.0).len(),
                format!("needs {nx} entries"),
            ));
        }
        self.schedule = Some(schedule);
        Ok(())
    }

    /// Sets the node references of every solver to the schedule's at the times of a plan
    /// starting at `start` (its constant reference to the one at `start`).
    fn apply_schedule(&mut self, start: f64) -> Result<()> {
        let Some(s) = &self.schedule else { return Ok(()) };
        let x_ref = s.at(start);
        let nodes = s.nodes(start, self.interval(), self.mpc.timing.intervals);
        let u_ref = vec![0.0; self.predictor.nu()];
        for solver in
            [Some(&mut self.lmpc), self.nmpc.as_mut(), self.initial.as_mut(), self.relaxed.as_mut()]
                .into_iter()
                .flatten()
        {
            solver.set_references(&x_ref, &u_ref)?;
            solver.set_node_references(&nodes)?;
        }
        Ok(())
    }

    /// Largest predicted joint angle (deg) over the nodes of `solver`'s plan.
    fn plan_angle(&self, solver: &SqpSolver<D>) -> Option<f64> {
        self.monitor.as_ref().map(|m| m.plan_max_angle(solver.states()).to_degrees())
    }

    /// Whether a plan with the predicted joint angle `angle` is within the model's range.
    fn within_range(&self, angle: Option<f64>) -> bool {
        match (angle, self.settings.plan_joint_limit_deg) {
            (Some(a), Some(limit)) => a <= limit,
            _ => true,
        }
    }

    /// Length of the plan's control intervals `Δt = τp / Nc` (s).
    pub fn interval(&self) -> f64 {
        self.mpc.timing.horizon / self.mpc.timing.intervals as f64
    }

    /// Predicts the modal state `x` forward by `duration` (s, ≥ 0) under the constant control
    /// `u`, with the nonlinear model (29) (for the LMPC too: its linearisation as predictor
    /// made the 3D LMPC diverge at ω0 = 0.5) and the controller's integrator (substeps scaled
    /// to `duration`).
    pub fn predict(&self, x: &[f64], u: &[f64], duration: f64) -> Result<Vec<f64>> {
        if !(duration.is_finite() && duration >= 0.0) {
            return Err(invalid("prediction duration", duration, "must be finite and ≥ 0"));
        }
        let mut out = x.to_vec();
        if duration == 0.0 {
            return Ok(out);
        }
        let base = &self.settings.integrator;
        let substeps = ((base.substeps as f64 * duration / self.interval()).ceil() as usize).max(1);
        let settings = IntegratorSettings { substeps, tail: None, ..base.clone() };
        let m = &self.predictor;
        let mut it = Integrator::new(m, &settings, duration)?;
        it.integrate(m, x, u, &mut out)?;
        if let Some(i) = out.iter().position(|v| !v.is_finite()) {
            return Err(invalid("predicted state", format!("entry {i} non-finite"), "diverged"));
        }
        Ok(out)
    }

    /// The settings.
    pub fn settings(&self) -> &ControllerSettings {
        &self.settings
    }

    /// The current plan of the solver whose control was applied last: nodes and controls.
    pub fn plan(&self) -> (&[DVector<f64>], &[DVector<f64>]) {
        match &self.nmpc {
            Some(s) => (s.states(), s.controls()),
            None => (self.lmpc.states(), self.lmpc.controls()),
        }
    }

    /// Solves the linear MPC's QP from `x0` (warm start from its plan shifted by `shift`).
    fn solve_lmpc(&mut self, x0: &[f64], shift: f64) -> Result<ocp_transcription::SqpStats> {
        if self.samples > 0 {
            self.lmpc.shift_time(shift)?;
        }
        Ok(self.lmpc.solve(x0)?)
    }

    /// Copies the linear MPC's plan into the NMPC iterate.
    fn nmpc_from_lmpc(&mut self) {
        if let Some(n) = self.nmpc.as_mut() {
            copy_plan(&self.lmpc, n);
        }
    }

    /// One sample: solves the OCP from the modal state `x0` at time `t` and returns the
    /// control to hold for `τs`, with the report of what was done.
    pub fn step(&mut self, t: f64, x0: &[f64]) -> Result<SampleReport> {
        self.step_from(t, t, x0)
    }

    /// One sample taken at time `t` whose plan starts at `start ≥ t` from the (predicted)
    /// modal state `x0` there (see [`crate::ControlGrid::Absolute`]); the warm start is the
    /// previous plan shifted by the difference of the plans' start times.
    pub fn step_from(&mut self, t: f64, start: f64, x0: &[f64]) -> Result<SampleReport> {
        if !(start.is_finite() && t.is_finite() && start >= t) {
            return Err(invalid("plan start", start, format!("must be finite and ≥ t = {t}")));
        }
        let shift = match self.last_start {
            Some(s) => (start - s).max(0.0),
            None => 0.0,
        };
        self.last_start = Some(start);
        let (clock, cpu, all) = (
            Instant::now(),
            ocp_transcription::thread_cpu_time(),
            ocp_transcription::process_cpu_time(),
        );
        let (evaluations0, trials0) = (self.evaluations(), self.line_search_trials());
        self.apply_schedule(start)?;
        let report = match self.settings.kind {
            ControllerKind::Lmpc => {
                let st = self.solve_lmpc(x0, shift)?;
                self.lmpc_report(t, start, st, status_name(st.status), Strategy::Qp)
            }
            ControllerKind::Nmpc => self.step_nmpc(t, start, x0, shift)?,
        };
        self.samples += 1;
        let (all_end, cpu_end) =
            (ocp_transcription::process_cpu_time(), ocp_transcription::thread_cpu_time());
        let wall = clock.elapsed().as_secs_f64();
        let solve_time = match (cpu, cpu_end) {
            (Some(a), Some(b)) => b - a,
            _ => wall,
        };
        let solve_cpu_all_threads = match (all, all_end) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        };
        let parallel =
            self.settings.parallel_intervals && self.settings.kind == ControllerKind::Nmpc;
        let timing = if parallel {
            let threads = rayon::current_num_threads().max(1);
            SolveTiming {
                solve_cpu_all_threads,
                solve_wall_time: wall,
                solve_threads: threads,
                solve_cpu_per_thread: if all.is_some() {
                    solve_cpu_all_threads / threads as f64
                } else {
                    wall
                },
            }
        } else {
            SolveTiming {
                solve_cpu_all_threads,
                solve_wall_time: wall,
                solve_threads: 1,
                solve_cpu_per_thread: solve_time,
            }
        };
        let evaluations = self.evaluations() - evaluations0;
        let line_search_trials = self.line_search_trials() - trials0;
        Ok(SampleReport { solve_time, timing, evaluations, line_search_trials, ..report })
    }

    fn step_nmpc(&mut self, t: f64, start: f64, x0: &[f64], shift: f64) -> Result<SampleReport> {
        if self.hold > 0 && self.samples > 0 {
            self.hold -= 1;
            let st = self.solve_lmpc(x0, shift)?;
            if let Some(n) = self.nmpc.as_mut() {
                // keep the NMPC's warm start aligned with the plans' start times
                n.shift_time(shift)?;
            }
            // real-time iteration: spend the held sample on one (not applied) NMPC iteration
            // from the measured state, so the NMPC resumes from its own plan, not from the
            // linear one a single Gauss–Newton step cannot turn into it; the full SQP resumes
            // from the linear plan and converges within its own iterations
            let accept = self.settings.accept_violation;
            let shadow = self.settings.real_time_iteration
                && self.nmpc.as_mut().is_some_and(|n| {
                    n.solve(x0).is_ok_and(|st| accepted(&st, accept))
                        && n.states().iter().all(|v| v.iter().all(|x| x.is_finite()))
                });
            if !shadow {
                self.nmpc_from_lmpc();
            }
            return Ok(self.lmpc_report(t, start, st, "Held".into(), Strategy::Held));
        }
        let mut lmpc_done = false;
        let mut initial_iterations = 0;
        if self.samples == 0 {
            initial_iterations = self.first_sample_start(x0, shift)?;
            lmpc_done = true;
        } else if let Some(n) = self.nmpc.as_mut() {
            n.shift_time(shift)?;
            if self.settings.rollout_intervals > 0 {
                let shifted = n.states().to_vec();
                let rolled = n.roll_out(x0, self.settings.rollout_intervals).is_ok()
                    && n.states().iter().all(|v| v.iter().all(|x| x.is_finite()));
                if !rolled {
                    n.states_mut().clone_from_slice(&shifted);
                }
            }
        }
        let first = match self.nmpc.as_mut() {
            Some(n) => n.solve(x0)?,
            None => return Err(invalid("controller", "lmpc", "no NMPC solver")),
        };
        let mut iterations = initial_iterations + first.iterations;
        let mut rejections = 0;
        let accept = self.settings.accept_violation;
        if accepted(&first, accept) {
            let angle = self.nmpc.as_ref().and_then(|n| self.plan_angle(n));
            if self.within_range(angle) {
                return Ok(self.nmpc_report(
                    t,
                    start,
                    first,
                    first.status,
                    Strategy::Sqp,
                    iterations,
                    (angle, rejections),
                ));
            }
            rejections += 1;
        }
        if !lmpc_done {
            self.solve_lmpc(x0, shift)?;
        }
        if let Some(r) = self.relaxed.as_mut() {
            copy_plan(&self.lmpc, r);
            let retry = r.solve(x0)?;
            iterations += retry.iterations;
            if accepted(&retry, accept) {
                let angle = self.relaxed.as_ref().and_then(|r| self.plan_angle(r));
                if self.within_range(angle) {
                    if let (Some(n), Some(r)) = (self.nmpc.as_mut(), self.relaxed.as_ref()) {
                        copy_plan(r, n);
                    }
                    return Ok(self.nmpc_report(
                        t,
                        start,
                        retry,
                        first.status,
                        Strategy::Relaxed,
                        iterations,
                        (angle, rejections),
                    ));
                }
                rejections += 1;
            }
        }
        // failure: apply the linear plan and restart the NMPC from it (then hold it for
        // `fallback_hold` samples); without the fallback (option) the NMPC's own last iterate
        // is applied and kept as the next warm start, unless it is not finite
        let own: Vec<f64> =
            self.nmpc.as_ref().map_or(Vec::new(), |n| n.first_control().iter().copied().collect());
        let fallback =
            self.settings.fallback_to_lmpc || own.is_empty() || own.iter().any(|v| !v.is_finite());
        let (u, st) = if fallback {
            self.nmpc_from_lmpc();
            if self.settings.fallback_to_lmpc {
                self.hold = self.settings.fallback_hold;
            }
            (self.lmpc.first_control().iter().copied().collect(), *self.lmpc.stats())
        } else {
            (own, first)
        };
        Ok(SampleReport {
            t,
            status: status_name(st.status),
            first_status: status_name(first.status),
            strategy: Strategy::Fallback,
            iterations,
            solve_time: 0.0,
            timing: SolveTiming::default(),
            cost: st.cost,
            kkt: st.kkt,
            u,
            plan_start: start,
            plan_joint_angle_deg: if fallback {
                self.plan_angle(&self.lmpc)
            } else {
                self.nmpc.as_ref().and_then(|n| self.plan_angle(n))
            },
            joint_limit_rejections: rejections,
            evaluations: Default::default(),
            line_search_trials: 0,
        })
    }

    #[allow(clippy::too_many_arguments)]
    /// The report of a sample that applies the linear MPC plan.
    fn lmpc_report(
        &self,
        t: f64,
        start: f64,
        st: ocp_transcription::SqpStats,
        first_status: String,
        strategy: Strategy,
    ) -> SampleReport {
        SampleReport {
            t,
            status: status_name(st.status),
            first_status,
            strategy,
            iterations: st.iterations,
            solve_time: 0.0,
            timing: SolveTiming::default(),
            cost: st.cost,
            kkt: st.kkt,
            u: self.lmpc.first_control().iter().copied().collect(),
            plan_start: start,
            plan_joint_angle_deg: self.plan_angle(&self.lmpc),
            joint_limit_rejections: 0,
            evaluations: Default::default(),
            line_search_trials: 0,
        }
    }

    fn nmpc_report(
        &self,
        t: f64,
        start: f64,
        st: ocp_transcription::SqpStats,
        first: SqpStatus,
        strategy: Strategy,
        iterations: usize,
        (plan_joint_angle_deg, joint_limit_rejections): (Option<f64>, usize),
    ) -> SampleReport {
        let u =
            self.nmpc.as_ref().map_or(Vec::new(), |n| n.first_control().iter().copied().collect());
        SampleReport {
            t,
            status: status_name(st.status),
            first_status: status_name(first),
            strategy,
            iterations,
            solve_time: 0.0,
            timing: SolveTiming::default(),
            cost: st.cost,
            kkt: st.kkt,
            u,
            plan_start: start,
            plan_joint_angle_deg,
            joint_limit_rejections,
            evaluations: Default::default(),
            line_search_trials: 0,
        }
    }

    /// This controller's solvers.
    fn solvers(&self) -> impl Iterator<Item = &SqpSolver<D>> + '_ {
        [self.nmpc.as_ref(), self.initial.as_ref(), self.relaxed.as_ref(), Some(&self.lmpc)]
            .into_iter()
            .flatten()
    }

    /// Model evaluations and factorisations of all this controller's solvers so far.
    fn evaluations(&self) -> ocp_transcription::Evaluations {
        self.solvers().map(|s| s.evaluations()).sum()
    }

    /// Line-search trial passes of all this controller's solvers so far.
    fn line_search_trials(&self) -> usize {
        self.solvers().map(|s| s.line_search_trials()).sum()
    }
}

/// Whether a solve left a usable plan: converged, or at the iteration limit with constraint
/// violation at most `accept`.
fn accepted(st: &ocp_transcription::SqpStats, accept: f64) -> bool {
    match st.status {
        SqpStatus::Solved | SqpStatus::RealTimeIteration => true,
        SqpStatus::MaxIterations => st.constraint_violation <= accept,
        _ => false,
    }
}

/// Whether every node and control of `solver`'s iterate is finite.
pub(super) fn plan_finite<D: Dynamics>(solver: &SqpSolver<D>) -> bool {
    solver.states().iter().chain(solver.controls()).all(|v| v.iter().all(|x| x.is_finite()))
}

/// Copies nodes and controls of `from` into `to` (same problem dimensions).
pub(super) fn copy_plan<D: Dynamics>(from: &SqpSolver<D>, to: &mut SqpSolver<D>) {
    for (d, s) in to.states_mut().iter_mut().zip(from.states()) {
        d.copy_from(s);
    }
    for (d, s) in to.controls_mut().iter_mut().zip(from.controls()) {
        d.copy_from(s);
    }
}
