//! `cargo xtask bench peers`: the first-sample optimal control problems of the paper's scenes
//! (`scenes/paper-{2d,3d}-mpc.toml` at several ω0) solved to convergence by flexmpc's SQP
//! from the linear MPC plan, with iterations, KKT residual, cost and time per solve and per
//! iteration (thread CPU time), and the same problems solved by CasADi (IPOPT with the exact
//! Hessian, `sqpmethod` with Gauss–Newton) when a `python3` with `casadi` is present.

use anyhow::{bail, Context, Result};
use mpc::RomDynamics;
use nalgebra::DVector;
use ocp_transcription::{Globalisation, Ocp, SqpMode, SqpSettings, SqpSolver, SqpStats};
use std::path::Path;

const USAGE: &str = "\
usage: cargo xtask bench peers [--variant NAME]... [--scene 2d|3d] [--omega0 W]...

Solves the first sample's problem of scenes/paper-2d-mpc.toml (ω0 = 0.5, 1, 2, 2.5) and
scenes/paper-3d-mpc.toml (ω0 = 0.5, 1, 1.5) to convergence (KKT tolerance 1e-8) from the
linear MPC plan and prints status, iterations, KKT, cost J*, CPU time per solve and per
iteration. --variant picks the globalisation (converge (default), merit, full, exact).";

/// One first-sample problem: the model, the OCP and the initial state.
pub struct Problem {
    /// `2d` or `3d`.
    pub scene: &'static str,
    /// Disturbance magnitude.
    pub omega0: f64,
    /// Controller model.
    pub model: RomDynamics,
    /// The OCP (33)–(35).
    pub ocp: Ocp,
    /// Initial modal state.
    pub x0: Vec<f64>,
    /// The scene's controller settings (integrator).
    pub controller: mpc::ControllerSettings,
}

/// Builds the first-sample problem of `scene` (`2d` or `3d`) at `omega0` through the scene
/// loader and the mpc crate's public API (the problem `flexmpc ocp --export` writes).
pub fn problem(root: &Path, scene: &'static str, omega0: f64) -> Result<Problem> {
    let file = root.join(format!("scenes/paper-{scene}-mpc.toml"));
    let s = flexmpc::scene::load(&file).with_context(|| format!("loading {}", file.display()))?;
    let overrides = flexmpc::control::Overrides { omega0: Some(omega0), ..Default::default() };
    let control = flexmpc::control::control_of(&s, &overrides)?;
    let setup = mpc::Setup::new(&control.scenario)?;
    let p = mpc::first_sample_problem(&setup, omega0, &control.controller)?;
    let model = RomDynamics::new(&setup.rom)?;
    let mpc = &control.scenario.mpc;
    let nu = p.u_min.len();
    let nx = p.x0.len();
    let mut ocp = Ocp::new(nx, nu, mpc.horizon, mpc.intervals)?;
    ocp.q = setup.weights.q.clone();
    ocp.r = setup.weights.r.clone();
    ocp.x_ref = setup.weights.x_ref.clone();
    ocp.u_ref = DVector::zeros(nu);
    ocp.u_min = DVector::from_vec(p.u_min.clone());
    ocp.u_max = DVector::from_vec(p.u_max.clone());
    Ok(Problem { scene, omega0, model, ocp, x0: p.x0, controller: control.controller })
}

/// CPU time of the calling thread (s), from `/proc/thread-self/schedstat`; wall time if absent.
fn cpu_now() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map(|ns| ns * 1e-9)
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs_f64())
                .unwrap_or(0.0)
        })
}

/// The SQP settings of a named variant.
fn settings(variant: &str, p: &Problem) -> Result<SqpSettings> {
    let base = SqpSettings {
        integrator: p.controller.integrator.clone(),
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

/// Solves `p` from the linear MPC plan (the controller's first-sample initial guess) with
/// `settings`; returns the stats, the thread CPU seconds of the SQP solve and `u_0`.
pub fn solve(p: &Problem, settings: SqpSettings) -> Result<(SqpStats, f64, Vec<f64>)> {
    let lq = SqpSettings {
        mode: SqpMode::LinearQuadratic,
        globalisation: Globalisation::FullStep,
        max_iterations: 2,
        integrator: settings.integrator.clone(),
        ..SqpSettings::default()
    };
    let mut lmpc = SqpSolver::new(p.model.clone(), p.ocp.clone(), lq)?;
    lmpc.solve(&p.x0)?;
    let mut nmpc = SqpSolver::new(p.model.clone(), p.ocp.clone(), settings)?;
    for (d, s) in nmpc.states_mut().iter_mut().zip(lmpc.states()) {
        d.copy_from(s);
    }
    for (d, s) in nmpc.controls_mut().iter_mut().zip(lmpc.controls()) {
        d.copy_from(s);
    }
    let c0 = cpu_now();
    let (st, _) = nmpc.solve_with_fallback_starts(&p.x0)?;
    let cpu = cpu_now() - c0;
    if std::env::var_os("PEERS_LOG").is_some() {
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
    Ok((st, cpu, nmpc.first_control().iter().copied().collect()))
}

/// `cargo xtask bench peers`.
pub fn main(args: &[String]) -> Result<()> {
    let mut variants: Vec<String> = Vec::new();
    let mut scenes: Vec<&'static str> = Vec::new();
    let mut omegas: Vec<f64> = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--variant" => variants.push(it.next().context("--variant needs a value")?.clone()),
            "--scene" => match it.next().map(String::as_str) {
                Some("2d") => scenes.push("2d"),
                Some("3d") => scenes.push("3d"),
                v => bail!("--scene takes 2d or 3d, found {v:?}"),
            },
            "--omega0" => {
                let v = it.next().context("--omega0 needs a value")?;
                omegas.push(v.parse().with_context(|| format!("--omega0 {v}"))?);
            }
            "-h" | "--help" => {
                println!("{USAGE}");
                return Ok(());
            }
            s => bail!("unknown argument `{s}`\n{USAGE}"),
        }
    }
    if variants.is_empty() {
        variants.push("merit".into());
    }
    if scenes.is_empty() {
        scenes = vec!["2d", "3d"];
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
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
            for v in &variants {
                let (st, cpu, _) = solve(&p, settings(v, &p)?)?;
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
            }
        }
    }
    Ok(())
}
