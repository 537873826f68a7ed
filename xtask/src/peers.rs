//! `cargo xtask bench peers`: the first-sample optimal control problems of the paper's scenes
//! (`scenes/paper-{2d,3d}-mpc.toml` and `scenes/paper-3d-mpc-paper-model.toml` at several ω0) solved to convergence by flexmpc's SQP
//! from the linear MPC plan, with iterations, KKT residual, cost and time per solve and per
//! iteration (thread CPU time), and the same problems solved by CasADi (`sqpmethod` with the
//! Gauss–Newton Hessian and compiled NLP functions, IPOPT with the exact Hessian) when a
//! `python3` with `casadi` is present.

use anyhow::{bail, Context, Result};
use mpc::{ExactDynamics, RomDynamics};
use nalgebra::{DMatrix, DVector};
use ocp_transcription::{
    Dynamics, Globalisation, IntegratorKind, Ocp, SqpMode, SqpSettings, SqpSolver, SqpStats, Start,
};
use std::path::{Path, PathBuf};

const USAGE: &str = "\
usage: cargo xtask bench peers [--variant NAME]... [--scene 2d|3d|3d-paper] [--omega0 W]...
                               [--python PATH | --no-casadi] [--peers LIST] [--qpsol NAME]
                               [--sqp-ls N] [--log] [--keep DIR] [--start-from DIR]

Solves the first sample's problem of scenes/paper-2d-mpc.toml (ω0 = 0.5, 1, 2, 2.5),
scenes/paper-3d-mpc.toml (`3d`: the exact-joints model, implicit midpoint) and
scenes/paper-3d-mpc-paper-model.toml (`3d-paper`) (3D: ω0 = 0.5, 1, 1.5) to convergence (KKT
tolerance 1e-8) from the linear MPC plan and prints status, iterations, KKT, cost J*, CPU time per solve and per
iteration. --variant picks the globalisation (converge (default), merit, full, exact, ...);
continuation-K solves along x0(α) = x_ref + α(x0 − x_ref), α = 1/K, 2/K, …, 1 with the
converge settings, each stage from the last one's solution (the first from the linear MPC
plan at x0(1/K)), and reports the summed iterations and the last stage's result;
converge-rollout / converge-filter-rollout start from the plan's controls rolled out from x0;
--log prints flexmpc's iteration log (cost, KKT, violation, step) to stderr.

When --python PATH is given, or `python3` can `import casadi`, each problem is exported to a
temporary directory (the controller model's export, `problem.json` with the OCP data, the
integrator (the Lawson propagator, or the implicit midpoint's Newton tolerance and a check of the
exact-joints right-hand side against flexmpc's), the start and flexmpc's solution) and solved by xtask/peers/casadi_peers.py from the same
start with CasADi's `sqpmethod` (Gauss–Newton Hessian, QP solver --qpsol, default hpipm;
NLP functions generated as C and compiled with gcc -O2 before the solve) and with IPOPT
(exact Hessian); a second table compares them with the first --variant (CPU time ratios
per solve and per iteration). --peers sqpmethod,ipopt (default both) picks the peers; gcc
must be on PATH for sqpmethod. --sqp-ls N sets sqpmethod's backtracking trials per line
search (max_iter_ls, CasADi's default 3: a search that fails after them takes the last trial).
--keep DIR writes each problem's export to DIR/SCENE-W and keeps it (with --no-casadi
only the export is written; `python casadi_peers.py DIR/SCENE-W` then runs the peers alone
and writes their solutions to DIR/SCENE-W/{sqpmethod,ipopt}_solution.json). --start-from DIR
starts flexmpc from DIR/SCENE-W/ipopt_solution.json instead of the linear MPC plan (does the
optimum IPOPT found stay a KKT point of flexmpc's NLP?).";

/// The controller model of a problem.
#[derive(Clone)]
pub enum PeerModel {
    /// The paper's model (14)–(29) and its reduced model (what the export writes).
    Paper(RomDynamics, Box<modal_rom::ModalRom>),
    /// The exact-joints model (theory.md §10).
    Exact(Box<ExactDynamics>),
}

/// One first-sample problem: the model, the OCP and the initial state.
pub struct Problem {
    /// `2d`, `3d` (the exact-joints model of scenes/paper-3d-mpc.toml) or `3d-paper`.
    pub scene: &'static str,
    /// Disturbance magnitude.
    pub omega0: f64,
    /// Controller model.
    pub model: PeerModel,
    /// The OCP (33)–(35).
    pub ocp: Ocp,
    /// Initial state.
    pub x0: Vec<f64>,
    /// The scene's controller settings (integrator).
    pub controller: mpc::ControllerSettings,
}

/// The scene file of `scene`.
fn scene_file(root: &Path, scene: &str) -> PathBuf {
    match scene {
        "3d-paper" => root.join("scenes/paper-3d-mpc-paper-model.toml"),
        _ => root.join(format!("scenes/paper-{scene}-mpc.toml")),
    }
}

/// Builds the first-sample problem of `scene` (`2d`, `3d` or `3d-paper`) at `omega0` through
/// the scene loader and the mpc crate's public API, on the scene's controller model (the
/// problem `flexmpc ocp --export` writes).
pub fn problem(root: &Path, scene: &'static str, omega0: f64) -> Result<Problem> {
    let file = scene_file(root, scene);
    let s = flexmpc::scene::load(&file).with_context(|| format!("loading {}", file.display()))?;
    let overrides = flexmpc::control::Overrides { omega0: Some(omega0), ..Default::default() };
    let control = flexmpc::control::control_of(&s, &overrides)?;
    let setup = mpc::Setup::new(&control.scenario)?;
    let mpc = &control.scenario.mpc;
    let (model, x0, weights, nodes, u_max) = match control.controller.model {
        mpc::ModelKind::Paper => {
            let p = mpc::first_sample_problem(&setup, omega0, &control.controller)?;
            let model = RomDynamics::new(&setup.rom)?;
            let w = setup.weights.clone();
            (PeerModel::Paper(model, Box::new(setup.rom.clone())), p.x0, w, None, p.u_max)
        }
        mpc::ModelKind::ExactJoints => {
            let f = mpc::first_sample_exact(&setup, omega0, &control.controller)?;
            let p = f.problem(&setup, omega0, &control.controller);
            let model = PeerModel::Exact(Box::new(f.dynamics.clone()));
            (model, f.x0, f.weights, p.x_ref_nodes, p.u_max)
        }
    };
    let nu = u_max.len();
    let nx = x0.len();
    let mut ocp = Ocp::new(nx, nu, mpc.timing.horizon, mpc.timing.intervals)?;
    ocp.q = weights.q.clone();
    ocp.r = weights.r.clone();
    ocp.u_ref = DVector::zeros(nu);
    ocp.u_min = -DVector::from_vec(u_max.clone());
    ocp.u_max = DVector::from_vec(u_max);
    match nodes {
        Some(n) => {
            ocp.x_ref = DVector::from_vec(n[0].clone());
            ocp.x_ref_nodes = n.into_iter().map(DVector::from_vec).collect();
        }
        None => ocp.x_ref = weights.x_ref.clone(),
    }
    // the peers map one interval function over the horizon, so every interval takes the
    // scene's own count (a real-time tail of coarser substeps is left out of this problem)
    let mut controller = control.controller;
    controller.integrator.tail = None;
    Ok(Problem { scene, omega0, model, ocp, x0, controller })
}

/// The SQP settings of a named variant; where the model or the integrator has no second
/// derivatives (the exact-joints model, the implicit midpoint rule) the exact Hessian is
/// replaced by the Gauss–Newton-then-quasi-Newton estimate, as in `flexmpc ocp --converge`.
fn settings(variant: &str, p: &Problem) -> Result<SqpSettings> {
    let mut s = named_settings(variant, p)?;
    let second_order = match &p.model {
        PeerModel::Paper(m, _) => m.has_second_order(),
        PeerModel::Exact(m) => m.has_second_order(),
    } && s.integrator.kind
        != ocp_transcription::IntegratorKind::ImplicitMidpoint;
    if !second_order && s.hessian != ocp_transcription::HessianApproximation::GaussNewton {
        s.hessian = SqpSettings::converge_quasi_newton(s.integrator.clone()).hessian;
    }
    Ok(s)
}

fn named_settings(variant: &str, p: &Problem) -> Result<SqpSettings> {
    // solved to convergence: the interval maps to round-off, whatever the scene's real-time
    // Newton tolerance
    let integrator = SqpSettings::converge(p.controller.integrator.clone()).integrator;
    let base = SqpSettings {
        integrator,
        max_iterations: 60,
        kkt_tolerance: 1e-8,
        ..SqpSettings::default()
    };
    Ok(match variant {
        "merit" => SqpSettings { max_iterations: 200, ..base },
        "filter" => SqpSettings {
            globalisation: Globalisation::filter(),
            qp_recovery: true,
            max_iterations: 200,
            ..base
        },
        "converge" => SqpSettings::converge(base.integrator.clone()),
        "converge-filter" => SqpSettings::converge_filter(base.integrator.clone()),
        "gn-converge" => SqpSettings {
            hessian: ocp_transcription::HessianApproximation::GaussNewton,
            ..SqpSettings::converge(base.integrator.clone())
        },
        "soc200" => {
            SqpSettings { max_iterations: 200, ..SqpSettings::converge(base.integrator.clone()) }
        }
        "full" => {
            SqpSettings { globalisation: Globalisation::FullStep, max_iterations: 200, ..base }
        }
        "exact" => SqpSettings {
            hessian: ocp_transcription::HessianApproximation::Exact,
            qp_form: ocp_transcription::QpForm::CondensedDense,
            ..base
        },
        "exact-filter" => SqpSettings {
            hessian: ocp_transcription::HessianApproximation::Exact,
            qp_form: ocp_transcription::QpForm::CondensedDense,
            globalisation: Globalisation::filter(),
            qp_recovery: true,
            ..base
        },
        "exact-soc" => SqpSettings {
            hessian: ocp_transcription::HessianApproximation::Exact,
            qp_form: ocp_transcription::QpForm::CondensedDense,
            ..SqpSettings::converge(base.integrator.clone())
        },
        "projected" => SqpSettings {
            hessian: ocp_transcription::HessianApproximation::ExactProjected,
            ..SqpSettings::converge(base.integrator.clone())
        },
        "projected-filter" => SqpSettings {
            hessian: ocp_transcription::HessianApproximation::ExactProjected,
            globalisation: Globalisation::filter(),
            ..SqpSettings::converge(base.integrator.clone())
        },
        "projected-full" => SqpSettings {
            hessian: ocp_transcription::HessianApproximation::ExactProjected,
            globalisation: Globalisation::FullStep,
            ..SqpSettings::converge(base.integrator.clone())
        },
        "converge-rollout" => SqpSettings::converge(base.integrator.clone()),
        "converge-filter-rollout" => SqpSettings::converge_filter(base.integrator.clone()),
        v if v.starts_with("continuation-") => SqpSettings::converge(base.integrator.clone()),
        v if v.starts_with("hybridmerit-") => {
            // the closed loops' merit (penalty only grows, no second-order correction)
            let switch_kkt: f64 = v["hybridmerit-".len()..]
                .trim_end_matches("-200")
                .parse()
                .with_context(|| format!("variant {v}"))?;
            SqpSettings {
                hessian: ocp_transcription::HessianApproximation::GaussNewtonThenExact {
                    switch_kkt,
                },
                globalisation: Globalisation::merit(),
                max_iterations: if v.ends_with("-200") { 200 } else { 60 },
                ..SqpSettings::converge(base.integrator.clone())
            }
        }
        v if v.starts_with("hybrid-") => {
            let (glob, tol) = match v.strip_prefix("hybrid-filter-") {
                Some(t) => (Globalisation::filter(), t),
                None => (Globalisation::merit_soc(), &v["hybrid-".len()..]),
            };
            let switch_kkt: f64 = tol.parse().with_context(|| format!("variant {v}"))?;
            SqpSettings {
                hessian: ocp_transcription::HessianApproximation::GaussNewtonThenExact {
                    switch_kkt,
                },
                globalisation: glob,
                ..SqpSettings::converge(base.integrator.clone())
            }
        }
        v => bail!("unknown variant `{v}`"),
    })
}

/// A primal point: shooting nodes `s_0 … s_Nc` and controls `u_0 … u_{Nc−1}`.
pub type Trajectory = (Vec<DVector<f64>>, Vec<DVector<f64>>);

/// A solve of one problem: the statistics, the start and the solution.
pub struct Solved {
    /// SQP statistics.
    pub stats: SqpStats,
    /// Thread CPU seconds of the SQP solve (the linear MPC start excluded).
    pub cpu: f64,
    /// Start the SQP iterated from: the linear MPC plan (or the `--start-from` point, or the
    /// rollout the fallback made when the dynamics were not finite at the plan's nodes).
    pub start: Trajectory,
    /// Solution nodes and controls.
    pub solution: Trajectory,
}

/// Solves `p` from the linear MPC plan (the controller's first-sample initial guess) with
/// `settings`.
pub fn solve(
    p: &Problem,
    settings: SqpSettings,
    log: bool,
    start_from: Option<&Path>,
    continuation: Option<usize>,
    rollout: bool,
) -> Result<Solved> {
    match &p.model {
        PeerModel::Paper(m, _) => {
            solve_on(m.clone(), p, settings, log, start_from, continuation, rollout)
        }
        PeerModel::Exact(m) => {
            solve_on((**m).clone(), p, settings, log, start_from, continuation, rollout)
        }
    }
}

fn solve_on<D: Dynamics + Clone>(
    model: D,
    p: &Problem,
    settings: SqpSettings,
    log: bool,
    start_from: Option<&Path>,
    continuation: Option<usize>,
    rollout: bool,
) -> Result<Solved> {
    let lq = SqpSettings {
        mode: SqpMode::LinearQuadratic,
        globalisation: Globalisation::FullStep,
        max_iterations: 2,
        integrator: settings.integrator.clone(),
        ..SqpSettings::default()
    };
    let mut lmpc = SqpSolver::new(model.clone(), p.ocp.clone(), lq)?;
    lmpc.solve(&p.x0)?;
    let mut nmpc = SqpSolver::new(model.clone(), p.ocp.clone(), settings)?;
    for (d, s) in nmpc.states_mut().iter_mut().zip(lmpc.states()) {
        d.copy_from(s);
    }
    for (d, s) in nmpc.controls_mut().iter_mut().zip(lmpc.controls()) {
        d.copy_from(s);
    }
    if let Some(file) = start_from {
        let (s, u) = read_solution(file, p)?;
        nmpc.states_mut().clone_from_slice(&s);
        nmpc.controls_mut().clone_from_slice(&u);
    }
    if rollout {
        nmpc.initialize_by_rollout(&p.x0)?;
    }
    let mut start = (nmpc.states().to_vec(), nmpc.controls().to_vec());
    if let Some(stages) = continuation {
        // homotopy in the initial state: x0(α) = x_ref + α(x0 − x_ref), each stage from the last
        let mut total = 0.0;
        let mut its = 0;
        for i in 1..=stages {
            let a = i as f64 / stages as f64;
            let xa: Vec<f64> =
                p.x0.iter().zip(p.ocp.x_ref.iter()).map(|(x, r)| r + a * (x - r)).collect();
            if i == 1 {
                let mut l = SqpSolver::new(model.clone(), p.ocp.clone(), lmpc.settings().clone())?;
                l.solve(&xa)?;
                nmpc.states_mut().clone_from_slice(l.states());
                nmpc.controls_mut().clone_from_slice(l.controls());
            }
            let (cpu, st) =
                ocp_transcription::thread_cpu_timed(|| nmpc.solve_with_fallback_starts(&xa));
            let (st, _) = st?;
            total += cpu;
            its += st.iterations;
            eprintln!(
                "continuation stage {i}/{stages}: {:?} it {} kkt {:.1e} J {:.10e}",
                st.status, st.iterations, st.kkt, st.cost
            );
        }
        let mut st = *nmpc.stats();
        st.iterations = its;
        return Ok(Solved {
            stats: st,
            cpu: total,
            start: start.clone(),
            solution: (nmpc.states().to_vec(), nmpc.controls().to_vec()),
        });
    }
    let (cpu, solved) =
        ocp_transcription::thread_cpu_timed(|| nmpc.solve_with_fallback_starts(&p.x0));
    let (st, used) = solved?;
    if used != Start::Given {
        // the start the SQP actually iterated from: the rollout the fallback made
        let mut roll = SqpSolver::new(model.clone(), p.ocp.clone(), settings_of(&nmpc))?;
        if used == Start::RolledOutReference {
            let u = p.ocp.u_ref.clone();
            roll.initialize_constant(&p.x0, u.as_slice())?;
        } else {
            roll.controls_mut().clone_from_slice(&start.1);
        }
        roll.initialize_by_rollout(&p.x0)?;
        start = (roll.states().to_vec(), roll.controls().to_vec());
    }
    if log {
        for l in nmpc.log() {
            eprintln!(
                "{:4} J {:.10e} kkt {:.2e} viol {:.2e} |dw| {:.2e} t {:.3e} qp {}",
                l.iteration,
                l.cost,
                l.kkt,
                l.constraint_violation,
                l.step_norm,
                l.step_length,
                l.qp_iterations
            );
        }
    }
    Ok(Solved {
        stats: st,
        cpu,
        start,
        solution: (nmpc.states().to_vec(), nmpc.controls().to_vec()),
    })
}

fn settings_of<D: Dynamics>(s: &SqpSolver<D>) -> SqpSettings {
    s.settings().clone()
}

/// Reads a primal point (`states`: `Nc + 1` vectors, `controls`: `Nc` vectors) written by
/// casadi_peers.py.
fn read_solution(file: &Path, p: &Problem) -> Result<Trajectory> {
    let text =
        std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)?;
    let read = |key: &str, count: usize, len: usize| -> Result<Vec<DVector<f64>>> {
        let rows = v[key].as_array().with_context(|| format!("{}: no `{key}`", file.display()))?;
        if rows.len() != count {
            bail!("{}: `{key}` has {} rows, expected {count}", file.display(), rows.len());
        }
        rows.iter()
            .map(|r| {
                let x: Vec<f64> = r
                    .as_array()
                    .with_context(|| format!("{}: `{key}` row is not an array", file.display()))?
                    .iter()
                    .map(|x| x.as_f64().unwrap_or(f64::NAN))
                    .collect();
                if x.len() != len || x.iter().any(|x| !x.is_finite()) {
                    bail!(
                        "{}: `{key}` row of length {} (expected {len}) or not finite",
                        file.display(),
                        x.len()
                    );
                }
                Ok(DVector::from_vec(x))
            })
            .collect()
    };
    let n = p.ocp.intervals;
    Ok((read("states", n + 1, p.ocp.nx())?, read("controls", n, p.ocp.nu())?))
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows()).map(|i| m.row(i).iter().copied().collect()).collect()
}

fn plan(v: &[DVector<f64>]) -> Vec<Vec<f64>> {
    v.iter().map(|x| x.iter().copied().collect()).collect()
}

/// Writes the controller model and `problem.json` (OCP data, integrator, start and flexmpc's
/// solution) of `p` to `dir`. Paper model: modal-rom's export and the Lawson propagator
/// `E = exp(L h/2)` of the model's linear part `L` as flexmpc computes it. Exact-joints model:
/// its export (theory.md §10), the implicit midpoint's Newton tolerance, and `rhs_check`:
/// states, inputs and flexmpc's right-hand side there ([`rhs_samples`]), for the peer to
/// compare its own right-hand side with.
fn export(p: &Problem, s: &Solved, settings: &SqpSettings, dir: &Path) -> Result<()> {
    let int = &settings.integrator;
    let o = &p.ocp;
    let mut json = serde_json::json!({
        "scene": p.scene,
        "omega0": p.omega0,
        "nx": o.nx(),
        "nu": o.nu(),
        "intervals": o.intervals,
        "interval": o.interval(),
        "substeps": int.substeps,
        "q": rows(&o.q),
        "r": rows(&o.r),
        "terminal": rows(&o.terminal),
        "x_ref": o.x_ref.iter().copied().collect::<Vec<_>>(),
        "x_ref_nodes": plan(&o.x_ref_nodes),
        "u_ref": o.u_ref.iter().copied().collect::<Vec<_>>(),
        "u_min": o.u_min.iter().copied().collect::<Vec<_>>(),
        "u_max": o.u_max.iter().copied().collect::<Vec<_>>(),
        "x0": p.x0,
        "start_states": plan(&s.start.0),
        "start_controls": plan(&s.start.1),
        "flexmpc_states": plan(&s.solution.0),
        "flexmpc_controls": plan(&s.solution.1),
        "flexmpc_cost": s.stats.cost,
    });
    let extra = match &p.model {
        PeerModel::Paper(model, rom) => {
            if int.kind != IntegratorKind::LawsonRk4 || int.adaptive.is_some() {
                bail!("the CasADi peer reproduces Lawson RK4 with fixed substeps, found {:?}", int);
            }
            rom.export(dir).with_context(|| format!("exporting the model to {}", dir.display()))?;
            let l = model.linear_part().context("the model has no linear part")?;
            let h = p.ocp.interval() / int.substeps as f64;
            let e = (&l * (0.5 * h)).exp();
            serde_json::json!({
                "model": "paper",
                "integrator": "lawson-rk4",
                "linear_part": rows(&l),
                "lawson_e": rows(&e),
            })
        }
        PeerModel::Exact(model) => {
            if int.kind != IntegratorKind::ImplicitMidpoint {
                bail!("the CasADi peer reproduces the exact-joints model's implicit midpoint rule, found {:?}", int);
            }
            let rom = model.rom();
            rom.export(dir).with_context(|| format!("exporting the model to {}", dir.display()))?;
            serde_json::json!({
                "model": "exact-joints",
                "integrator": "implicit-midpoint",
                "newton_tolerance": int.newton_tolerance,
                "newton_max_iterations": int.newton_max_iterations,
                "rhs_check": rhs_samples(rom, p, s)?,
            })
        }
    };
    if let (Some(m), Some(e)) = (json.as_object_mut(), extra.as_object()) {
        m.extend(e.clone());
    }
    std::fs::write(dir.join("problem.json"), serde_json::to_string(&json)?)
        .with_context(|| format!("writing {}/problem.json", dir.display()))?;
    Ok(())
}

/// States and inputs at which the peer checks its exact-joints right-hand side, with flexmpc's
/// values there: flexmpc's optimal nodes and controls, and synthetic states (velocities and
/// forces of the size of the initial state's, inputs at ±bounds) with the joints turned from
/// their reference by 0.3 … 3.0 rad about varied axes and the root turned arbitrarily. States
/// outside the model's range are skipped (the model reports them).
fn rhs_samples(
    rom: &modal_rom::ExactJointsRom,
    p: &Problem,
    s: &Solved,
) -> Result<Vec<serde_json::Value>> {
    let n = rom.n_state();
    let nu = rom.n_inputs();
    let mut points: Vec<(Vec<f64>, Vec<f64>, &str)> = s
        .solution
        .0
        .iter()
        .zip(&s.solution.1)
        .map(|(x, u)| (x.iter().copied().collect(), u.iter().copied().collect(), "flexmpc optimum"))
        .collect();
    let scale = p.x0[..rom.n_p() + rom.n_p2()].iter().fold(0.0f64, |m, v| m.max(v.abs())).max(0.1);
    let quat = |angle: f64, axis: [f64; 3]| {
        let nrm = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let sn = (0.5 * angle).sin() / nrm;
        [(0.5 * angle).cos(), sn * axis[0], sn * axis[1], sn * axis[2]]
    };
    let mul = |a: [f64; 4], b: [f64; 4]| {
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    };
    for (i, angle) in [0.3, 0.8, 1.2, 1.6, 2.0, 2.4, 2.8, 3.0].into_iter().enumerate() {
        let seed = 1.0 + i as f64;
        let mut x = rom.reference_state();
        for (c, v) in x[..rom.n_p() + rom.n_p2()].iter_mut().enumerate() {
            *v = scale * (seed * (c as f64 + 1.7)).sin();
        }
        let axis = [(seed * 0.9).sin(), (seed * 1.3).cos(), 0.5 + (seed * 2.1).sin()];
        for j in 0..rom.n_joints() {
            let o = rom.joint_offset(j);
            let r = [x[o], x[o + 1], x[o + 2], x[o + 3]];
            x[o..o + 4].copy_from_slice(&mul(r, quat(angle, axis)));
        }
        if rom.has_root() {
            let o = rom.root_offset();
            let r = [x[o], x[o + 1], x[o + 2], x[o + 3]];
            x[o..o + 4].copy_from_slice(&mul(r, quat(2.0 * angle, [axis[2], -axis[0], axis[1]])));
        }
        let u: Vec<f64> =
            (0..nu).map(|c| p.ocp.u_max[c] * if (c + i) % 2 == 0 { 1.0 } else { -0.5 }).collect();
        points.push((x, u, "synthetic"));
    }
    let mut out = Vec::new();
    for (x, u, kind) in points {
        let mut f = vec![0.0; n];
        if rom.rhs(&x, &u, &mut f).is_ok() {
            out.push(serde_json::json!({ "kind": kind, "x": x, "u": u, "f": f }));
        }
    }
    Ok(out)
}

/// The Python to run the CasADi peer with, or why there is none.
fn find_python(explicit: Option<PathBuf>) -> std::result::Result<PathBuf, String> {
    let py = explicit.unwrap_or_else(|| PathBuf::from("python3"));
    match std::process::Command::new(&py)
        .args(["-c", "import casadi; print(casadi.__version__)"])
        .output()
    {
        Ok(o) if o.status.success() => Ok(py),
        Ok(o) => Err(format!(
            "`{} -c 'import casadi'` failed: {}",
            py.display(),
            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("")
        )),
        Err(e) => Err(format!("cannot run `{}`: {e}", py.display())),
    }
}

/// Whether `gcc` (CasADi's `shell` JIT compiler for the generated C code) runs.
fn find_gcc() -> std::result::Result<(), String> {
    match std::process::Command::new("gcc").arg("--version").output() {
        Ok(o) if o.status.success() => Ok(()),
        Ok(_) => Err("`gcc --version` failed".into()),
        Err(e) => Err(format!("cannot run `gcc`: {e}")),
    }
}

/// Runs the CasADi peer on an exported problem; returns its JSON report.
fn run_casadi(py: &Path, script: &Path, dir: &Path, extra: &[String]) -> Result<serde_json::Value> {
    let o = std::process::Command::new(py)
        .arg(script)
        .arg(dir)
        .args(extra)
        .output()
        .with_context(|| format!("running {}", py.display()))?;
    if !o.status.success() {
        bail!("{} failed: {}", script.display(), String::from_utf8_lossy(&o.stderr));
    }
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out.lines().rev().find(|l| l.starts_with('{')).context("no JSON line")?;
    Ok(serde_json::from_str(line)?)
}

/// `cargo xtask bench peers`.
pub fn main(args: &[String]) -> Result<()> {
    let mut variants: Vec<String> = Vec::new();
    let mut scenes: Vec<&'static str> = Vec::new();
    let mut omegas: Vec<f64> = Vec::new();
    let mut python: Option<PathBuf> = None;
    let mut casadi = true;
    let mut log = false;
    let mut keep: Option<PathBuf> = None;
    let mut start_from: Option<PathBuf> = None;
    let mut selected: Vec<String> = vec!["sqpmethod".into(), "ipopt".into()];
    let mut qpsol: Option<String> = None;
    let mut sqp_ls: Option<usize> = None;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--variant" => variants.push(it.next().context("--variant needs a value")?.clone()),
            "--scene" => match it.next().map(String::as_str) {
                Some("2d") => scenes.push("2d"),
                Some("3d") => scenes.push("3d"),
                Some("3d-paper") => scenes.push("3d-paper"),
                v => bail!("--scene takes 2d, 3d or 3d-paper, found {v:?}"),
            },
            "--omega0" => {
                let v = it.next().context("--omega0 needs a value")?;
                omegas.push(v.parse().with_context(|| format!("--omega0 {v}"))?);
            }
            "--python" => python = Some(it.next().context("--python needs a path")?.into()),
            "--no-casadi" => casadi = false,
            "--peers" => {
                let v = it.next().context("--peers needs a list (sqpmethod,ipopt)")?;
                if v.split(',').any(|p| p != "sqpmethod" && p != "ipopt") {
                    bail!("--peers takes sqpmethod and/or ipopt, comma-separated, found `{v}`");
                }
                selected = v.split(',').map(str::to_string).collect();
            }
            "--qpsol" => {
                let v = it.next().context("--qpsol needs a CasADi QP solver name")?;
                qpsol = Some(v.clone());
            }
            "--sqp-ls" => {
                let v = it.next().context("--sqp-ls needs a count")?;
                sqp_ls = Some(v.parse().with_context(|| format!("--sqp-ls {v}"))?);
            }
            "--log" => log = true,
            "--keep" => keep = Some(it.next().context("--keep needs a directory")?.into()),
            "--start-from" => {
                start_from = Some(it.next().context("--start-from needs a directory")?.into())
            }
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(());
            }
            s => bail!("unknown argument `{s}`\n{USAGE}"),
        }
    }
    if variants.is_empty() {
        variants.push("converge".into());
    }
    if scenes.is_empty() {
        scenes = vec!["2d", "3d"];
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("peers/casadi_peers.py");
    let python = if casadi {
        match find_python(python) {
            Ok(p) => Some(p),
            Err(why) => {
                println!("casadi not found: {why}; skipping the sqpmethod and IPOPT columns");
                None
            }
        }
    } else {
        None
    };
    if python.is_some() && selected.iter().any(|p| p == "sqpmethod") {
        if let Err(why) = find_gcc() {
            println!("{why}; skipping the compiled sqpmethod column");
            selected.retain(|p| p != "sqpmethod");
        }
    }
    let python = if selected.is_empty() { None } else { python };
    let mut peer_args = vec!["--only".to_string(), selected.join(",")];
    if let Some(q) = qpsol {
        peer_args.extend(["--qpsol".to_string(), q]);
    }
    if let Some(n) = sqp_ls {
        peer_args.extend(["--max-iter-ls".to_string(), n.to_string()]);
    }
    let mut peers: Vec<String> = Vec::new();
    println!("| scene | ω0 | variant | status | iterations | KKT | J* | CPU s/solve | CPU ms/iteration | integration / condensing / QP ms/it | trial passes/it |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for scene in scenes {
        let list: Vec<f64> = if !omegas.is_empty() {
            omegas.clone()
        } else if scene == "2d" {
            vec![0.5, 1.0, 2.0, 2.5]
        } else {
            vec![0.5, 1.0, 1.5]
        };
        for &w in &list {
            let p = problem(&root, scene, w)?;
            debug_assert!(p.scene == scene && p.omega0 == w);
            for (vi, v) in variants.iter().enumerate() {
                let set = settings(v, &p)?;
                let from = start_from
                    .as_ref()
                    .map(|d| d.join(format!("{scene}-{w}")).join("ipopt_solution.json"));
                let cont = v.strip_prefix("continuation-").and_then(|k| k.parse().ok());
                let rollout = v.ends_with("-rollout");
                let sol = solve(&p, set.clone(), log, from.as_deref(), cont, rollout)?;
                let (st, cpu) = (&sol.stats, sol.cpu);
                let per = 1e3 / st.iterations.max(1) as f64;
                println!(
                    "| {scene} | {w} | {v} | {:?} | {} | {:.1e} | {:.10e} | {:.3} | {:.1} | {:.1} / {:.1} / {:.1} | {:.1} |",
                    st.status,
                    st.iterations,
                    st.kkt,
                    st.cost,
                    cpu,
                    cpu * per,
                    st.time_integration * per,
                    st.time_condensing * per,
                    st.time_qp * per,
                    // interval integrations beyond the one linearisation per iteration (and
                    // the final one), in whole passes over the horizon
                    (st.integrator_calls as f64 / p.ocp.intervals as f64
                        - (st.iterations + 1) as f64)
                        / st.iterations.max(1) as f64,
                );
                if vi == 0 && (python.is_some() || keep.is_some()) {
                    let dir = match &keep {
                        Some(k) => k.join(format!("{scene}-{w}")),
                        None => std::env::temp_dir()
                            .join(format!("flexmpc-peers-{}-{scene}-{w}", std::process::id())),
                    };
                    std::fs::create_dir_all(&dir)
                        .with_context(|| format!("creating {}", dir.display()))?;
                    export(&p, &sol, &set, &dir)?;
                    if let Some(py) = &python {
                        let r = run_casadi(py, &script, &dir, &peer_args)?;
                        peers.push(peer_row(scene, w, v, st, cpu, &r));
                    }
                    if keep.is_none() {
                        let _ = std::fs::remove_dir_all(&dir);
                    }
                }
            }
        }
    }
    if !peers.is_empty() {
        println!();
        println!("| scene | ω0 | NLP check: J rel. diff / max defect at flexmpc's optimum | peer | J* (rel. diff to flexmpc) | status, inf_pr / inf_du | iterations | CPU s/solve | CPU ms/iteration | peer / flexmpc CPU per solve, per iteration | code generation + gcc s |");
        println!("|---|---|---|---|---|---|---|---|---|---|---|");
        for r in &peers {
            println!("{r}");
        }
    }
    Ok(())
}

/// The rows of the comparison table for one problem: flexmpc, then each peer the script ran.
fn peer_row(
    scene: &str,
    w: f64,
    v: &str,
    st: &SqpStats,
    cpu: f64,
    r: &serde_json::Value,
) -> String {
    let f = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
    let its = st.iterations.max(1) as f64;
    let mut rows = vec![format!(
        "| {scene} | {w} | {:.1e} / {:.1e} | flexmpc `{v}` | {:.10e} | {:?}, KKT {:.1e} | {} | {cpu:.3} | {:.1} | — | — |",
        f("check_cost_rel"),
        f("check_defect"),
        st.cost,
        st.status,
        st.kkt,
        st.iterations,
        1e3 * cpu / its,
    )];
    for (key, name) in [("sqpmethod", "sqpmethod GN"), ("ipopt", "IPOPT exact")] {
        let p = &r[key];
        if p.is_null() {
            continue;
        }
        let g = |k: &str| p[k].as_f64().unwrap_or(f64::NAN);
        let it = p["iterations"].as_u64().unwrap_or(0);
        let (j, t) = (g("cost"), g("cpu_s"));
        let per = t / it.max(1) as f64;
        let name = match p["qpsol"].as_str() {
            Some(q) => format!("{name} ({q})"),
            None => name.to_string(),
        };
        let build = if p["build_cpu_s"].is_null() {
            "—".to_string()
        } else {
            format!("{:.1} CPU / {:.1} wall", g("build_cpu_s"), g("build_wall_s"))
        };
        rows.push(format!(
            "| {scene} | {w} | | {name} | {j:.10e} ({:+.1e}) | {} {:.1e} / {:.1e} | {it} | {t:.3} | {:.1} | {:.1} / {:.1} | {build} |",
            (j - st.cost) / st.cost.abs(),
            p["status"].as_str().unwrap_or("?"),
            g("inf_pr"),
            g("inf_du"),
            1e3 * per,
            t / cpu,
            per / (cpu / its),
        ));
    }
    rows.join("\n")
}
