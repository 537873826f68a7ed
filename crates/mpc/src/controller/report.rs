//! What one sample's solve did: the applied path, the solver's counters, the measured times
//! and the work.

use serde::{Deserialize, Serialize};

/// Which path produced the applied control of a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Strategy {
    /// The linear MPC's QP.
    Qp,
    /// The NMPC's first attempt (warm start from the shifted plan, line search).
    Sqp,
    /// The NMPC's retry from the linear MPC plan with sub-relaxation and LM.
    Relaxed,
    /// Every NMPC attempt failed: the linear MPC plan was applied.
    Fallback,
    /// Within [`crate::ControllerSettings::fallback_hold`] samples of a fallback: the linear MPC
    /// plan was applied without trying the NMPC.
    Held,
}

/// What one sample's solve did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SampleReport {
    /// Sample time (s).
    pub t: f64,
    /// Status of the solve that produced the control (`Debug` name of [`ocp_transcription::SqpStatus`]).
    pub status: String,
    /// Status of the NMPC's first attempt (same as `status` for the LMPC).
    pub first_status: String,
    /// Path that produced the applied control.
    pub strategy: Strategy,
    /// SQP iterations over all attempts (QPs for the LMPC).
    pub iterations: usize,
    /// CPU time the calling thread spent on the whole sample's solve (all attempts) (s), from
    /// [`ocp_transcription::thread_cpu_time`]: not inflated by other processes sharing the
    /// cores. With [`crate::ControllerSettings::parallel_intervals`] off every solve runs on the
    /// calling thread, so this is all the solve's CPU time; with it on, the work of the pool's
    /// threads is missing here ([`SolveTiming`] has the measures that count it). Wall time
    /// where the thread clock is unavailable (off Unix).
    pub solve_time: f64,
    /// The sample's solve measured by the whole process's CPU and by the wall clock.
    #[serde(flatten)]
    pub timing: SolveTiming,
    /// Optimal cost of the accepted plan.
    pub cost: f64,
    /// KKT residual of the accepted plan.
    pub kkt: f64,
    /// Applied control `u_0`.
    pub u: Vec<f64>,
    /// Time at which the plan starts (its first control takes over): the sample time, or
    /// with [`crate::ControlGrid::Absolute`] the next grid time `kΔt ≥ t` (s).
    pub plan_start: f64,
    /// Largest joint angle between links predicted over the applied plan's nodes (deg), when
    /// the controller has a [`crate::validity::JointMonitor`].
    pub plan_joint_angle_deg: Option<f64>,
    /// NMPC attempts of this sample that converged (or were acceptable) but were rejected
    /// because their plan left [`crate::ControllerSettings::plan_joint_limit_deg`].
    pub joint_limit_rejections: usize,
    /// Model evaluations and Newton-matrix factorisations of the whole sample (every attempt,
    /// the warm start's rollout included): its work in units that do not depend on the
    /// machine or its load, next to [`SampleReport::solve_time`].
    #[serde(default)]
    pub evaluations: ocp_transcription::Evaluations,
    /// Line-search trial passes of the whole sample (every attempt): one per trial step
    /// integrated over the shooting intervals, so a sample whose full step was rejected shows
    /// one more than its iterations. The same for any thread count.
    #[serde(default)]
    pub line_search_trials: usize,
}

/// One sample's solve (all attempts) measured three ways besides the calling thread's CPU
/// ([`SampleReport::solve_time`]). Where the solve runs on `n > 1` threads
/// ([`crate::ControllerSettings::parallel_intervals`]) the calling thread's CPU misses the pool's
/// work, so the time per sample on `n` cores is stated as `solve_cpu_all_threads / n` (the
/// CPU each core spent on average) beside the wall time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SolveTiming {
    /// CPU time of every thread of the process during the solve (s), from
    /// [`ocp_transcription::process_cpu_time`]. It counts the pool's idle spinning between
    /// the parallel sections (CPU taken from other work, so it is counted), and in a sweep
    /// the other runs going on at the same time; 0 where the clock is unavailable.
    pub solve_cpu_all_threads: f64,
    /// Wall-clock time of the solve (s): includes the time other processes hold the cores.
    pub solve_wall_time: f64,
    /// Threads the solve ran on: the rayon pool's size with
    /// [`crate::ControllerSettings::parallel_intervals`] on (NMPC), else 1.
    pub solve_threads: usize,
    /// The solve's CPU time per thread (s): with [`crate::ControllerSettings::parallel_intervals`]
    /// on, `solve_cpu_all_threads / solve_threads` (the calling thread waits while the pool
    /// works); off, the calling thread's CPU ([`SampleReport::solve_time`]).
    pub solve_cpu_per_thread: f64,
}
