//! Study (d), closed-loop cost against compute time: the controller configurations (LMPC,
//! real-time-iteration NMPC, full SQP NMPC with iteration limits) on the paper's 2D scenario
//! (§5.2) and, on the 3D scenario (§5.3), the LMPC, the full SQP and the real-time spatial NMPC
//! with the paper's `k_u` and the `k_u = 1` option; the closed-loop cost of a run.

pub use mpc::{run as closed_loop, PlantKind, RunResult, Setup};
use mpc::{ControllerKind, ControllerSettings, Scenario};

use super::{median, Result};

/// A named controller configuration.
pub fn configs(quick: bool) -> Vec<(String, ControllerSettings)> {
    let mut out = vec![("LMPC".to_string(), ControllerSettings::of(ControllerKind::Lmpc))];
    let mut rti = ControllerSettings::full_sqp();
    rti.real_time_iteration = true;
    out.push(("NMPC RTI".into(), rti));
    let limits: &[usize] = if quick { &[3] } else { &[1, 2, 3, 5, 10] };
    for &m in limits {
        let mut c = ControllerSettings::full_sqp();
        c.max_iterations = m;
        out.push((format!("NMPC SQP ≤{m} it."), c));
    }
    out
}

/// Closed-loop cost `∫ (V_state + ½ k_u |u|²) dt` over the run, divided by `T · V(0)`, and the
/// time average of `V_state / V(0)`.
pub fn closed_loop_cost(r: &RunResult, ku: f64) -> (f64, f64) {
    let rec = &r.records;
    if rec.len() < 2 {
        return (f64::NAN, f64::NAN);
    }
    let (mut jv, mut ju) = (0.0, 0.0);
    for w in rec.windows(2) {
        let dt = w[1].t - w[0].t;
        jv += 0.5 * dt * (w[0].v_state + w[1].v_state);
        // the control recorded at a row is held over the interval that starts there
        ju += dt * 0.5 * ku * w[0].u.iter().map(|v| v * v).sum::<f64>();
    }
    let t = rec[rec.len() - 1].t - rec[0].t;
    let v0 = rec[0].v_state;
    ((jv + ju) / (t * v0), jv / (t * v0))
}

/// Per-run figures of a closed loop: solve time per sample (median, mean; s), SQP iterations
/// per sample, and the two costs of [`closed_loop_cost`].
pub struct Figures {
    /// Median solve time per sample (s).
    pub median: f64,
    /// Mean solve time per sample (s).
    pub mean: f64,
    /// SQP iterations per sample.
    pub iterations: f64,
    /// `J / (T·V(0))`.
    pub cost: f64,
    /// Time average of `V_state / V(0)`.
    pub mean_v: f64,
}

/// The figures of a closed loop, its cost measured with the input weight `ku`.
pub fn figures(r: &RunResult, ku: f64) -> Figures {
    let mut times: Vec<f64> = r.samples.iter().map(|x| x.solve_time).collect();
    let n = times.len().max(1) as f64;
    let mean = times.iter().sum::<f64>() / n;
    let iterations = r.samples.iter().map(|x| x.iterations as f64).sum::<f64>() / n;
    let (cost, mean_v) = closed_loop_cost(r, ku);
    Figures { median: median(&mut times), mean, iterations, cost, mean_v }
}

/// The setups of the 3D part: the paper's 3D scenario with `elements` per link, and the same
/// with the documented option `k_u = 1` (`mpc::SPATIAL_INPUT_WEIGHT`).
pub fn setups_3d(elements: usize) -> Result<(Setup, Setup)> {
    let paper = Setup::new(&Scenario::paper_3d(elements)?)?;
    let mut option_sc = Scenario::paper_3d(elements)?;
    option_sc.mpc.cost.ku = mpc::SPATIAL_INPUT_WEIGHT;
    Ok((paper, Setup::new(&option_sc)?))
}

/// The 3D configurations on the setups of [`setups_3d`]: the LMPC and the real-time spatial
/// NMPC with `k_u = 1`, and outside the quick tier the real-time spatial NMPC with the paper's
/// `k_u` and the library default (full SQP).
pub fn configs_3d<'a>(
    quick: bool,
    paper: &'a Setup,
    option: &'a Setup,
) -> Vec<(&'static str, &'a Setup, ControllerSettings)> {
    let spatial = ControllerSettings::real_time_spatial();
    let mut configs: Vec<(&str, &Setup, ControllerSettings)> = vec![
        ("LMPC", paper, ControllerSettings::of(ControllerKind::Lmpc)),
        ("NMPC RTI spatial, k_u = 1", option, spatial.clone()),
    ];
    if !quick {
        configs.extend([
            ("NMPC RTI spatial", paper, spatial),
            ("NMPC SQP ≤10 it. (full SQP)", paper, ControllerSettings::full_sqp()),
        ]);
    }
    configs
}

/// The paper's 2D scenario with `elements` per link.
pub fn setup_2d(elements: usize) -> Result<Setup> {
    Ok(Setup::new(&Scenario::paper_2d(elements)?)?)
}
