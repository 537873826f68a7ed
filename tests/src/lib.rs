//! Cross-crate verification suite of flexmpc.
//!
//! A verification *case* is a named numerical experiment (`<crate>/<case>`) that returns one
//! or more [`Metric`]s, each a measured value compared with a tolerance that the method's
//! order or conditioning justifies. `cargo xtask verify` runs them in release mode and prints a
//! table (CI runs the quick tier).
//!
//! Each crate contributes its cases in its own module; [`all_cases`] gathers them. The
//! experiments behind the cases live beside them (`beam::studies`, `multibody::studies`), and
//! [`perf`] holds the numerics of `cargo xtask bench`.

pub mod beam;
pub mod exact_joints;
pub mod kick;
pub mod modal;
pub mod mpc;
pub mod mpc_2d;
pub mod multibody;
pub mod ocp;
pub mod perf;
pub mod reconfiguration;
pub mod scenes;
pub mod stress;

use std::time::Instant;

/// How expensive a case is: `Quick` runs in CI (`cargo xtask verify --quick`, seconds each),
/// `Full` only in `cargo xtask verify` / `--full` (minutes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tier {
    /// Seconds in release mode; run in CI.
    Quick,
    /// Longer sweeps and refinements; run locally.
    Full,
}

/// How a metric's value is compared with its tolerance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Comparison {
    /// Pass when `value <= tolerance` (errors, drifts, residuals).
    AtMost,
    /// Pass when `value >= tolerance` (convergence orders, margins).
    AtLeast,
}

/// One measured quantity of a case.
#[derive(Clone, Debug)]
pub struct Metric {
    /// What was measured, e.g. `relative energy drift`.
    pub metric: String,
    /// The measured value.
    pub value: f64,
    /// The bound it is compared with.
    pub tolerance: f64,
    /// Direction of the comparison.
    pub comparison: Comparison,
}

impl Metric {
    /// A metric that passes when `value <= tolerance`.
    pub fn at_most(metric: impl Into<String>, value: f64, tolerance: f64) -> Self {
        Self { metric: metric.into(), value, tolerance, comparison: Comparison::AtMost }
    }

    /// A metric that passes when `value >= tolerance`.
    pub fn at_least(metric: impl Into<String>, value: f64, tolerance: f64) -> Self {
        Self { metric: metric.into(), value, tolerance, comparison: Comparison::AtLeast }
    }

    /// Whether the metric passes. A NaN value never passes.
    pub fn pass(&self) -> bool {
        match self.comparison {
            Comparison::AtMost => self.value <= self.tolerance,
            Comparison::AtLeast => self.value >= self.tolerance,
        }
    }
}

/// The outcome of running one case: its metrics, or the error that stopped it.
pub type CaseOutcome = Result<Vec<Metric>, String>;

/// A named verification case.
#[derive(Clone, Copy)]
pub struct Case {
    /// `<crate>/<case>`, e.g. `intrinsic-beam/energy-conservation`.
    pub name: &'static str,
    /// Cost tier.
    pub tier: Tier,
    /// Runs the experiment.
    pub run: fn() -> CaseOutcome,
}

/// One row of a report: a case's metric, or the error that stopped the case.
#[derive(Clone, Debug)]
pub struct Row {
    /// Case name.
    pub case: String,
    /// Metric (or `error` when the case failed to run).
    pub metric: Metric,
    /// Wall time of the whole case in seconds (repeated on each of its rows).
    pub seconds: f64,
}

/// Thread CPU time of the calling thread (s); `None` off Linux.
pub use ocp_transcription::thread_cpu_time as thread_cpu;

/// Every case of every crate, in crate order.
pub fn all_cases() -> Vec<Case> {
    let mut cases = Vec::new();
    cases.extend(beam::cases());
    cases.extend(multibody::cases());
    cases.extend(modal::cases());
    cases.extend(exact_joints::cases());
    cases.extend(ocp::cases());
    cases.extend(mpc::cases());
    cases.extend(mpc_2d::cases());
    cases.extend(kick::cases());
    cases.extend(reconfiguration::cases());
    cases.extend(scenes::cases());
    cases.extend(stress::cases());
    cases
}

/// Runs one case and flattens it into rows; an error becomes a failing row.
pub fn run_case(case: &Case) -> Vec<Row> {
    let start = Instant::now();
    let outcome =
        std::panic::catch_unwind(case.run).unwrap_or_else(|_| Err("the case panicked".to_string()));
    let seconds = start.elapsed().as_secs_f64();
    match outcome {
        Ok(metrics) if !metrics.is_empty() => metrics
            .into_iter()
            .map(|metric| Row { case: case.name.to_string(), metric, seconds })
            .collect(),
        Ok(_) => vec![Row {
            case: case.name.to_string(),
            metric: Metric::at_most("error: the case returned no metric", f64::NAN, 0.0),
            seconds,
        }],
        Err(message) => vec![Row {
            case: case.name.to_string(),
            metric: Metric::at_most(format!("error: {message}"), f64::NAN, 0.0),
            seconds,
        }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn case_names_are_unique_and_prefixed() {
        let cases = all_cases();
        let prefixes = [
            "intrinsic-beam/",
            "multibody-constraints/",
            "modal-rom/",
            "ocp-transcription/",
            "mpc/",
        ];
        for (i, a) in cases.iter().enumerate() {
            assert!(prefixes.iter().any(|p| a.name.starts_with(p)), "bad case name {}", a.name);
            for b in &cases[i + 1..] {
                assert_ne!(a.name, b.name, "duplicate case name");
            }
        }
    }

    #[test]
    fn nan_never_passes() {
        assert!(!Metric::at_most("x", f64::NAN, 1.0).pass());
        assert!(!Metric::at_least("x", f64::NAN, 1.0).pass());
        assert!(Metric::at_least("order", 2.0, 1.8).pass());
    }
}
