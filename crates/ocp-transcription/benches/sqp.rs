//! Criterion benches of the SQP on a model with the modal ROM's structure, and the tables of
//! docs/ocp-transcription.md (integrator error against cost, QP forms, time per iteration
//! against nx and Nc, adaptive substeps, the 3D-sized iteration).
//!
//! `cargo bench -p ocp-transcription --bench sqp` runs the criterion benches (criterion's own
//! arguments after `--`, e.g. `-- sqp_iteration_3d`: the 3D-sized iteration with line search
//! on one and two threads, timed in CPU time).
//! `cargo bench -p ocp-transcription --bench sqp -- --tables LIST` prints the tables instead;
//! see [`USAGE`].

use criterion::Criterion;
use nalgebra::{DMatrix, DVector};
use ocp_transcription::samples::{seeded, ModalLike};
use ocp_transcription::{
    interval_error, process_cpu_time, AdaptiveSubsteps, Dynamics, Globalisation, Integrator,
    IntegratorKind, IntegratorSettings, Ocp, QpForm, SqpMode, SqpSettings, SqpSolver, SqpStatus,
};
use rand::Rng;

/// A random state with entries in [−a, a] and controls in [−1, 1].
fn operating_point(nx: usize, nu: usize, a: f64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = seeded(2024);
    let x = (0..nx).map(|_| rng.random_range(-a..a)).collect();
    let u = (0..nu).map(|_| rng.random_range(-1.0..1.0)).collect();
    (x, u)
}

/// The ROM-structured sample (`ModalLike::rom_like`: block pattern and tensor fill of the
/// paper's 3D ROM, tensor scale calibrated on its one-interval errors, see
/// `ModalLike::paper_sized_rom`), frequencies up to 175 rad/s.
fn model(nx: usize) -> ModalLike {
    ModalLike::rom_like(nx, 5, 175.0, 0.1, 7).expect("valid")
}

/// Max row sum of the nonlinear Jacobian `∂(N(x)x)/∂x` at `x` (the real 3D ROM: 78, 157, 314
/// at the initial states of ω0 = 0.5, 1, 2).
fn nonlinear_row_sum(m: &ModalLike, x: &[f64]) -> f64 {
    let (nx, nu) = (m.nx(), m.nu());
    let (mut fx, mut fu) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
    m.jacobians(x, &vec![0.0; nu], &mut fx, &mut fu);
    let jg = fx - m.linear_part().expect("modal");
    jg.row_iter().map(|r| r.iter().map(|v| v.abs()).sum::<f64>()).fold(0.0, f64::max)
}

/// The paper's OCP sizes: τp = 6 s, Nc = 24, |u| ≤ 5, small state weight.
fn ocp(nx: usize, nc: usize) -> Ocp {
    let mut ocp = Ocp::new(nx, 5, 6.0, nc).expect("valid");
    ocp.q = DMatrix::identity(nx, nx);
    ocp.r = DMatrix::identity(5, 5) * 0.1;
    ocp.u_min = DVector::from_element(5, -5.0);
    ocp.u_max = DVector::from_element(5, 5.0);
    ocp
}

fn integrator(kind: IntegratorKind, substeps: usize) -> IntegratorSettings {
    IntegratorSettings::new(kind, substeps)
}

/// Mean CPU seconds of `f`: batches of runs until at least 0.3 s of CPU time has been
/// accumulated (the scheduler's CPU clock ticks coarsely), at least `reps` runs.
fn median_time(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let (mut total, mut runs) = (0.0, 0usize);
    while total < 0.3 || runs < reps {
        total += ocp_transcription::thread_cpu_timed(&mut f).0;
        runs += 1;
    }
    total / runs as f64
}

fn integrator_table() {
    let m = model(61);
    let dt = 0.25;
    println!("\n## One-interval error (Δt = 0.25 s) against cost, nx = 61, nu = 5, ω ≤ 175 rad/s");
    let mut rng = seeded(99);
    let u_rand: Vec<f64> = (0..5).map(|_| rng.random_range(-1.0..1.0)).collect();
    let states: Vec<(String, Vec<f64>, Vec<f64>)> = vec![
        ("rotating ω0 = 1, u = 0".into(), m.rotating_state(1.0).unwrap(), vec![0.0; 5]),
        ("rotating ω0 = 2, u = 0".into(), m.rotating_state(2.0).unwrap(), vec![0.0; 5]),
        ("rotating ω0 = 2, u ∈ [−1, 1]".into(), m.rotating_state(2.0).unwrap(), u_rand.clone()),
        (
            "rotating ω0 = 2, u = ±5".into(),
            m.rotating_state(2.0).unwrap(),
            vec![5.0, -5.0, 5.0, -5.0, 5.0],
        ),
        ("rotating ω0 = 1, u ∈ [−1, 1]".into(), m.rotating_state(1.0).unwrap(), u_rand.clone()),
    ];
    for (name, x, u) in states {
        let mut reference = vec![0.0; 61];
        let mut int =
            Integrator::new(&m, &integrator(IntegratorKind::LawsonRk4, 8192), dt).unwrap();
        int.integrate(&m, &x, &u, &mut reference).unwrap();
        let rn = reference.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        println!(
            "\nstate: {name} (‖x⁺‖∞ = {rn:.3}, max row sum of ∂(N(x)x)/∂x {:.0}); error = ‖x⁺ − x⁺_ref‖∞ / ‖x⁺_ref‖∞ (reference Lawson × 8192); µs CPU per interval with A, B",
            nonlinear_row_sum(&m, &x)
        );
        println!("| substeps | RK4 | Lawson RK4 | implicit midpoint |");
        println!("|---|---|---|---|");
        for n in [4, 8, 12, 16, 20, 24, 32, 48, 64] {
            print!("| {n} |");
            for kind in
                [IntegratorKind::Rk4, IntegratorKind::LawsonRk4, IntegratorKind::ImplicitMidpoint]
            {
                let mut int = Integrator::new(&m, &integrator(kind, n), dt).unwrap();
                let mut xe = vec![0.0; 61];
                let err = match int.integrate(&m, &x, &u, &mut xe) {
                    Ok(()) => {
                        xe.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max)
                            / rn
                    }
                    Err(_) => f64::NAN,
                };
                let mut a = DMatrix::zeros(61, 61);
                let mut b = DMatrix::zeros(61, 5);
                let t = median_time(5, || {
                    let _ = int.integrate_with_sensitivities(&m, &x, &u, &mut xe, &mut a, &mut b);
                });
                let e = if err.is_finite() && err < 10.0 {
                    format!("{err:.1e}")
                } else {
                    "unstable".into()
                };
                print!(" {e}, {:.0} |", t * 1e6);
            }
            println!();
        }
    }
}

/// The paper-sized problem on `model(nx)`: the rotating state of `omega0` and the OCP towards
/// rest (reference: the rest state, `qξ_0 = 1`) on `nc` intervals.
fn problem(nx: usize, nc: usize, omega0: f64) -> (ModalLike, Vec<f64>, Ocp) {
    let m = model(nx);
    let x = m.rotating_state(omega0).expect("rom-like");
    let mut o = ocp(nx, nc);
    let (mm, nq2, _) = m.rom_blocks().expect("rom-like");
    o.x_ref[mm + nq2] = 1.0;
    (m, x, o)
}

/// A solver at the rotating state of ω0 = 0.5, warm started by simulation with u = 0. (From
/// ω0 ≈ 1 on, this model's free rotation is unstable over τp = 6 s and the condensed QP fails:
/// `Auto` then takes the sparse QP.)
fn solver(nx: usize, nc: usize, settings: SqpSettings) -> (SqpSolver<ModalLike>, Vec<f64>) {
    let (m, x, o) = problem(nx, nc, 0.5);
    let mut s = SqpSolver::new(m, o, settings).expect("valid");
    s.initialize_by_simulation(&x, &[0.0; 5]).expect("finite");
    (s, x)
}

/// Median (total, integration, condensing, QP) ms of one real-time iteration from the same
/// iterate: total is CPU time, the split scales it by the solver's wall-clock shares.
fn time_iteration(
    nx: usize,
    nc: usize,
    settings: SqpSettings,
    reps: usize,
) -> (f64, f64, f64, f64, usize) {
    let (mut s, x) = solver(nx, nc, settings);
    let states: Vec<DVector<f64>> = s.states().to_vec();
    let controls: Vec<DVector<f64>> = s.controls().to_vec();
    let (mut cpu, mut wall, mut ti, mut tc, mut tq, mut qi, mut runs) =
        (0.0, 0.0, 0.0, 0.0, 0.0, 0, 0usize);
    while cpu < 0.3 || runs < reps {
        s.states_mut().clone_from_slice(&states);
        s.controls_mut().clone_from_slice(&controls);
        let (c, st) = ocp_transcription::thread_cpu_timed(|| s.solve(&x).expect("valid x0"));
        cpu += c;
        wall += st.time_total;
        ti += st.time_integration;
        tc += st.time_condensing;
        tq += st.time_qp;
        qi = st.qp_iterations;
        assert_eq!(st.status, ocp_transcription::SqpStatus::RealTimeIteration, "{st:?}");
        runs += 1;
    }
    let per = 1e3 / runs as f64;
    let f = cpu / wall;
    (cpu * per, f * ti * per, f * tc * per, f * tq * per, qi)
}

/// One real-time iteration with a full step: linearise (24 integrations with sensitivities),
/// condense, QP, step.
fn rti(kind: IntegratorKind, substeps: usize, form: QpForm) -> SqpSettings {
    SqpSettings {
        mode: SqpMode::RealTimeIteration,
        qp_form: form,
        integrator: integrator(kind, substeps),
        globalisation: ocp_transcription::Globalisation::FullStep,
        ..SqpSettings::default()
    }
}

fn qp_table() {
    println!("\n## One SQP iteration (RTI), nx = 61, nu = 5, Nc = 24, τp = 6 s: QP forms (ms)");
    println!("| integrator | QP form | total | integration | condensing | QP | QP iterations |");
    println!("|---|---|---|---|---|---|---|");
    for (kind, n) in [
        (IntegratorKind::LawsonRk4, 20),
        (IntegratorKind::LawsonRk4, 24),
        (IntegratorKind::Rk4, 64),
    ] {
        for form in [QpForm::CondensedDense, QpForm::CondensedClarabel, QpForm::SparseClarabel] {
            if kind == IntegratorKind::Rk4 && form != QpForm::CondensedDense {
                continue;
            }
            let reps = if form == QpForm::SparseClarabel { 3 } else { 7 };
            let (t, ti, tc, tq, qi) = time_iteration(61, 24, rti(kind, n, form), reps);
            println!("| {kind:?} × {n} | {form:?} | {t:.1} | {ti:.1} | {tc:.1} | {tq:.1} | {qi} |");
        }
    }
    // with the merit line search (its trials are state-only integrations of all intervals)
    let merit = SqpSettings {
        globalisation: ocp_transcription::Globalisation::merit(),
        ..rti(IntegratorKind::LawsonRk4, 20, QpForm::CondensedDense)
    };
    let (t, ti, tc, tq, qi) = time_iteration(61, 24, merit, 7);
    println!("| LawsonRk4 × 20, merit line search | CondensedDense | {t:.1} | {ti:.1} | {tc:.1} | {tq:.1} | {qi} |");
    let lawson16 = rti(IntegratorKind::LawsonRk4, 16, QpForm::CondensedDense);
    let (t, ti, tc, tq, qi) = time_iteration(61, 24, lawson16, 7);
    println!("| LawsonRk4 × 16 | CondensedDense | {t:.1} | {ti:.1} | {tc:.1} | {tq:.1} | {qi} |");
    // wall clock with the intervals on the thread pool (2 cores here)
    for n in [20, 24] {
        let settings = SqpSettings {
            parallel_intervals: true,
            ..rti(IntegratorKind::LawsonRk4, n, QpForm::CondensedDense)
        };
        let (mut s, x) = solver(61, 24, settings);
        let states: Vec<DVector<f64>> = s.states().to_vec();
        let controls: Vec<DVector<f64>> = s.controls().to_vec();
        let mut walls: Vec<f64> = (0..21)
            .map(|_| {
                s.states_mut().clone_from_slice(&states);
                s.controls_mut().clone_from_slice(&controls);
                s.solve(&x).expect("valid x0").time_total * 1e3
            })
            .collect();
        walls.sort_by(|a, b| a.partial_cmp(b).unwrap());
        println!("| LawsonRk4 × {n}, parallel intervals | CondensedDense | {:.1} (wall, median) | | | | |", walls[10]);
    }
}

fn sweep_table() {
    println!("\n## Time per SQP iteration (RTI, Lawson RK4 × 20, condensed dense QP), ms: total (integration / condensing / QP)");
    print!("| nx \\ Nc |");
    let ncs = [10, 24, 50];
    for nc in ncs {
        print!(" {nc} |");
    }
    println!();
    println!("|---|---|---|---|");
    for nx in [11, 31, 61, 91, 121] {
        print!("| {nx} |");
        for nc in ncs {
            let (t, ti, tc, tq, _) = time_iteration(
                nx,
                nc,
                rti(IntegratorKind::LawsonRk4, 20, QpForm::CondensedDense),
                3,
            );
            print!(" {t:.1} ({ti:.1} / {tc:.1} / {tq:.1}) |");
        }
        println!();
    }
}

/// The adaptive table calibrated for Lawson RK4 on `model(nx)` (tolerance 1e-3, counts 8–48).
fn calibrated_table(m: &ModalLike) -> AdaptiveSubsteps {
    AdaptiveSubsteps::calibrate(
        m,
        &integrator(IntegratorKind::LawsonRk4, 16),
        0.25,
        &m.calibration_samples(5).expect("rom-like"),
        &[12, 16, 24],
        512,
        1e-3,
        8,
        48,
    )
    .expect("calibration")
}

/// A plan from the rotating state of `omega0` towards rest on `model(nx)`, Nc = 24: 40
/// full-step SQP iterations with the sparse QP (the condensed Hessian of the free rotation is
/// ill-conditioned), Lawson RK4 × `substeps`. The solver, the initial state, the status and
/// the KKT residual.
fn converged_plan(
    nx: usize,
    omega0: f64,
    substeps: usize,
) -> (SqpSolver<ModalLike>, Vec<f64>, SqpStatus, f64) {
    let (m, x, o) = problem(nx, 24, omega0);
    let settings = SqpSettings {
        qp_form: QpForm::SparseClarabel,
        globalisation: Globalisation::FullStep,
        integrator: integrator(IntegratorKind::LawsonRk4, substeps),
        max_iterations: 40,
        ..SqpSettings::default()
    };
    let mut s = SqpSolver::new(m, o, settings).expect("valid");
    s.initialize_by_simulation(&x, &[0.0; 5]).expect("finite");
    let st = s.solve(&x).expect("valid x0");
    (s, x, st.status, st.kkt)
}

/// State-adapted substeps on realistic plans: per-interval counts and one-interval errors
/// against a Lawson × 512 reference, and the time of one RTI iteration from the plan.
fn adaptive_table() {
    let m = model(61);
    let table = calibrated_table(&m);
    println!(
        "\n## Adaptive substeps (Lawson RK4, tolerance 1e-3): calibrated c_x = {:.3}, c_u = {:.1}, c_l = {:.2}",
        table.state_constant, table.input_constant, table.fast_constant
    );
    let mut reference =
        Integrator::new(&m, &integrator(IntegratorKind::LawsonRk4, 512), 0.25).unwrap();
    // the criterion bench's iterate: free rotation from ω0 = 0.5 simulated with u = 0
    {
        let settings = IntegratorSettings {
            adaptive: Some(table.clone()),
            ..integrator(IntegratorKind::LawsonRk4, 16)
        };
        let mut int = Integrator::new(&m, &settings, 0.25).unwrap();
        let (mut x, u) = (m.rotating_state(0.5).unwrap(), [0.0; 5]);
        let (mut xr, mut xe) = (vec![0.0; 61], vec![0.0; 61]);
        let (mut total, mut worst) = (0, 0.0_f64);
        for _ in 0..24 {
            reference.integrate(&m, &x, &u, &mut xr).unwrap();
            let n = int.choose_substeps(&m, &x, &u, Some(&xr));
            int.set_substeps(n).unwrap();
            int.integrate(&m, &x, &u, &mut xe).unwrap();
            worst = worst.max(interval_error(&xe, &xr));
            total += n;
            x.copy_from_slice(&xe);
        }
        println!(
            "\ncriterion iterate (free rotation from ω0 = 0.5, u = 0): mean substeps {:.1}, max one-interval error {worst:.1e}",
            total as f64 / 24.0
        );
    }
    for omega0 in [0.5, 1.0, 2.0] {
        let (plan, x, status, kkt) = converged_plan(61, omega0, 24);
        println!("\nplan from ω0 = {omega0}: {status:?}, KKT {kkt:.1e}");
        let states: Vec<DVector<f64>> = plan.states().to_vec();
        let controls: Vec<DVector<f64>> = plan.controls().to_vec();
        let adaptive = IntegratorSettings {
            adaptive: Some(table.clone()),
            ..integrator(IntegratorKind::LawsonRk4, 16)
        };
        let mut int = Integrator::new(&m, &adaptive, 0.25).unwrap();
        let mut fixed: Vec<Integrator> = [16, 20]
            .iter()
            .map(|&n| Integrator::new(&m, &integrator(IntegratorKind::LawsonRk4, n), 0.25).unwrap())
            .collect();
        let (mut xr, mut xe) = (vec![0.0; 61], vec![0.0; 61]);
        let (mut worst, mut worst16, mut worst20, mut total) = (0.0_f64, 0.0_f64, 0.0_f64, 0);
        let mut counts = Vec::new();
        for k in 0..24 {
            let (sk, uk, sn) =
                (states[k].as_slice(), controls[k].as_slice(), states[k + 1].as_slice());
            let n = int.choose_substeps(&m, sk, uk, Some(sn));
            int.set_substeps(n).unwrap();
            reference.integrate(&m, sk, uk, &mut xr).unwrap();
            int.integrate(&m, sk, uk, &mut xe).unwrap();
            worst = worst.max(interval_error(&xe, &xr));
            fixed[0].integrate(&m, sk, uk, &mut xe).unwrap();
            worst16 = worst16.max(interval_error(&xe, &xr));
            fixed[1].integrate(&m, sk, uk, &mut xe).unwrap();
            worst20 = worst20.max(interval_error(&xe, &xr));
            total += n;
            counts.push(n);
        }
        println!(
            "counts {counts:?}: mean {:.1}; max one-interval error adaptive {worst:.1e}, fixed 16 {worst16:.1e}, fixed 20 {worst20:.1e}",
            total as f64 / 24.0
        );
        println!("| integrator | QP form | status | total ms | integration | condensing | QP | mean substeps |");
        println!("|---|---|---|---|---|---|---|---|");
        for (label, isettings) in [
            ("adaptive", adaptive.clone()),
            ("Lawson × 16", integrator(IntegratorKind::LawsonRk4, 16)),
            ("Lawson × 20", integrator(IntegratorKind::LawsonRk4, 20)),
        ] {
            for form in [QpForm::CondensedDense, QpForm::Auto] {
                let mut settings = rti(IntegratorKind::LawsonRk4, 16, form);
                settings.integrator = isettings.clone();
                let mut s = SqpSolver::new(m.clone(), plan.ocp().clone(), settings).unwrap();
                let (mut cpu, mut wall, mut ti, mut tc, mut tq, mut runs) =
                    (0.0, 0.0, 0.0, 0.0, 0.0, 0usize);
                let mut last = None;
                while cpu < 0.5 || runs < 5 {
                    s.states_mut().clone_from_slice(&states);
                    s.controls_mut().clone_from_slice(&controls);
                    let (c, st) =
                        ocp_transcription::thread_cpu_timed(|| s.solve(&x).expect("valid x0"));
                    cpu += c;
                    wall += st.time_total;
                    ti += st.time_integration;
                    tc += st.time_condensing;
                    tq += st.time_qp;
                    runs += 1;
                    last = Some(st);
                }
                let st = last.expect("ran");
                let (per, f) = (1e3 / runs as f64, cpu / wall);
                println!(
                    "| {label} | {form:?} | {:?} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
                    st.status,
                    cpu * per,
                    f * ti * per,
                    f * tc * per,
                    f * tq * per,
                    st.mean_substeps
                );
            }
        }
    }
}

/// The 3D-sized problem of the paper (nx = 53 = the real 3D ROM's size, nu = 5, Nc = 24,
/// τp = 6 s, Lawson × 16) on the ROM-structured sample, and a plan from the rotating state
/// of ω0 = 1 ([`converged_plan`]) to iterate from: the solver (settings `settings`), the
/// initial state and the plan.
#[allow(clippy::type_complexity)]
fn plan_3d(
    settings: SqpSettings,
) -> (SqpSolver<ModalLike>, Vec<f64>, Vec<DVector<f64>>, Vec<DVector<f64>>) {
    let (p, x, _, _) = converged_plan(53, 1.0, 16);
    // one real-time iteration from a perturbed plan: the merit line search has work to do
    let states: Vec<DVector<f64>> =
        p.states().iter().map(|s| s.map(|v| v * 1.02)).collect::<Vec<_>>();
    let controls: Vec<DVector<f64>> = p.controls().iter().map(|u| u.map(|v| 0.9 * v)).collect();
    let s = SqpSolver::new(p.model().clone(), p.ocp().clone(), settings).expect("valid");
    (s, x, states, controls)
}

/// One SQP iteration of the 3D-sized problem as the closed loop's full SQP takes it:
/// Gauss–Newton linearisation (24 intervals with sensitivities), condensing, dense QP, merit
/// line search (its trial integrations included), step.
fn iteration_3d_settings(parallel: bool) -> SqpSettings {
    SqpSettings {
        mode: SqpMode::RealTimeIteration,
        integrator: integrator(IntegratorKind::LawsonRk4, 16),
        globalisation: Globalisation::merit(),
        qp_form: QpForm::CondensedDense,
        parallel_intervals: parallel,
        ..SqpSettings::default()
    }
}

/// Table: CPU ms of one 3D-sized iteration (see [`iteration_3d_settings`]) on one thread and
/// on a pool of two, with the split integration (linearisation and line-search trials) /
/// condensing / QP (wall-clock shares of the solver's timers scaled to the CPU total) and the
/// trial passes of the line search. At least `seconds` of CPU time per row; with `dump`, the
/// iterate after one iteration, every value in round-trip precision, to `<dump>.<threads>`
/// (to compare implementations bit for bit).
fn iteration_3d_table(seconds: f64, dump: Option<&str>) {
    println!(
        "\n## One SQP iteration with merit line search, nx = 53, nu = 5, Nc = 24, Lawson × 16, \
         from a plan of ω0 = 1 (ms CPU; two threads: all threads' CPU)"
    );
    println!("| threads | CPU total | CPU per thread | integration | condensing | QP | line-search trials |");
    println!("|---|---|---|---|---|---|---|");
    for threads in [1usize, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
        pool.install(|| {
            let (mut s, x, states, controls) = plan_3d(iteration_3d_settings(threads > 1));
            let (mut cpu, mut wall, mut ti, mut tc, mut tq, mut trials, mut runs) =
                (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0usize);
            while cpu < seconds || runs < 10 {
                s.states_mut().clone_from_slice(&states);
                s.controls_mut().clone_from_slice(&controls);
                let c0 = process_cpu_time().unwrap_or(0.0);
                let st = s.solve(&x).expect("valid x0");
                cpu += process_cpu_time().unwrap_or(0.0) - c0;
                wall += st.time_total;
                ti += st.time_integration;
                tc += st.time_condensing;
                tq += st.time_qp;
                trials += st.integrator_calls as f64 / 24.0 - 1.0;
                runs += 1;
            }
            if let Some(path) = dump {
                s.states_mut().clone_from_slice(&states);
                s.controls_mut().clone_from_slice(&controls);
                s.solve(&x).expect("valid x0");
                let mut out = String::new();
                for v in s.states().iter().chain(s.controls()).flat_map(|v| v.iter()) {
                    out.push_str(&format!("{v:?}\n"));
                }
                std::fs::write(format!("{path}.{threads}"), out).expect("writable dump path");
            }
            let per = 1e3 / runs as f64;
            let f = cpu / wall;
            println!(
                "| {threads} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
                cpu * per,
                cpu * per / threads as f64,
                f * ti * per,
                f * tc * per,
                f * tq * per,
                trials / runs as f64
            );
        });
    }
}

/// Criterion: the 3D-sized iteration, one thread (thread CPU) and two threads (CPU of all
/// threads of the process: the work; per thread it is half when the pool is balanced).
fn bench_iteration_3d(c: &mut Criterion) {
    let mut g = c.benchmark_group("sqp_iteration_3d_nx53_nu5_nc24_lawson16");
    g.sample_size(20);
    for threads in [1usize, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
        let (mut s, x, states, controls) = plan_3d(iteration_3d_settings(threads > 1));
        let name = if threads == 1 { "1thread_thread_cpu" } else { "2threads_process_cpu" };
        g.bench_function(name, |b| {
            b.iter_custom(|iters| {
                pool.install(|| {
                    let clock = if threads == 1 {
                        ocp_transcription::thread_cpu_time
                    } else {
                        process_cpu_time
                    };
                    let (mut cpu, w0) = (0.0, std::time::Instant::now());
                    for _ in 0..iters {
                        s.states_mut().clone_from_slice(&states);
                        s.controls_mut().clone_from_slice(&controls);
                        let c0 = clock();
                        std::hint::black_box(s.solve(&x).expect("valid x0"));
                        cpu += match (c0, clock()) {
                            (Some(a), Some(b)) => b - a,
                            _ => f64::NAN,
                        };
                    }
                    if cpu.is_finite() {
                        std::time::Duration::from_secs_f64(cpu)
                    } else {
                        w0.elapsed()
                    }
                })
            })
        });
    }
    g.finish();
}

fn bench_sqp(c: &mut Criterion) {
    let mut g = c.benchmark_group("sqp_iteration_nx61_nu5_nc24");
    g.sample_size(20);
    for (kind, n, form) in [
        (IntegratorKind::LawsonRk4, 20, QpForm::CondensedDense),
        (IntegratorKind::LawsonRk4, 20, QpForm::CondensedClarabel),
        (IntegratorKind::Rk4, 64, QpForm::CondensedDense),
    ] {
        let (mut s, x) = solver(61, 24, rti(kind, n, form));
        let states: Vec<DVector<f64>> = s.states().to_vec();
        let controls: Vec<DVector<f64>> = s.controls().to_vec();
        g.bench_function(format!("{kind:?}x{n}_{form:?}"), |b| {
            b.iter(|| {
                s.states_mut().clone_from_slice(&states);
                s.controls_mut().clone_from_slice(&controls);
                s.solve(&x).expect("valid x0")
            })
        });
    }
    // state-adapted counts (calibrated table, tolerance 1e-3) from the same iterate
    let mut settings = rti(IntegratorKind::LawsonRk4, 16, QpForm::CondensedDense);
    settings.integrator.adaptive = Some(calibrated_table(&model(61)));
    let (mut s, x) = solver(61, 24, settings);
    let states: Vec<DVector<f64>> = s.states().to_vec();
    let controls: Vec<DVector<f64>> = s.controls().to_vec();
    g.bench_function("LawsonAdaptive_CondensedDense", |b| {
        b.iter(|| {
            s.states_mut().clone_from_slice(&states);
            s.controls_mut().clone_from_slice(&controls);
            s.solve(&x).expect("valid x0")
        })
    });
    g.finish();
    let m = model(61);
    let x = m.rotating_state(2.0).expect("rom-like");
    let (_, u) = operating_point(61, 5, 0.3);
    let mut g = c.benchmark_group("interval_with_sensitivities_nx61");
    for (kind, n) in [(IntegratorKind::LawsonRk4, 20), (IntegratorKind::Rk4, 64)] {
        let mut int = Integrator::new(&m, &integrator(kind, n), 0.25).unwrap();
        let mut xe = vec![0.0; 61];
        let mut a = DMatrix::zeros(61, 61);
        let mut b = DMatrix::zeros(61, 5);
        g.bench_function(format!("{kind:?}x{n}"), |bch| {
            bch.iter(|| int.integrate_with_sensitivities(&m, &x, &u, &mut xe, &mut a, &mut b))
        });
    }
    g.finish();
    let _ = m.nx();
}

/// Runs the criterion benches.
fn benches() {
    let mut c = Criterion::default().configure_from_args();
    bench_iteration_3d(&mut c);
    bench_sqp(&mut c);
    c.final_summary();
}

/// The bench's own arguments (criterion's are passed on to criterion).
const USAGE: &str = "\
usage: cargo bench -p ocp-transcription --bench sqp -- [CRITERION ARGS]
       cargo bench -p ocp-transcription --bench sqp -- --tables LIST [--iter3d-seconds S]
                                                      [--iter3d-dump PATH]

  (no --tables)        the criterion benches, with criterion's arguments (filter, --list, ...)
  --tables LIST        print these tables instead, comma-separated, in this order: int
                       (one-interval error against cost), qp (QP forms), adaptive (adaptive
                       substeps), sweep (time per iteration against nx and Nc), iter3d (the
                       3D-sized iteration on one and two threads); `all` for every one
  --iter3d-seconds S   iter3d: at least S s of CPU time per row (default 1; longer to profile)
  --iter3d-dump PATH   iter3d: also write the iterate after one iteration, every value in
                       round-trip precision, to PATH.1 and PATH.2 (one and two threads)";

/// The tables to print and the options of `iter3d`, read from the bench's arguments.
#[derive(Debug, PartialEq)]
struct Tables {
    which: Vec<&'static str>,
    iter3d_seconds: f64,
    iter3d_dump: Option<String>,
}

/// The table names `--tables` accepts, in the order they are printed.
const TABLE_NAMES: [&str; 5] = ["int", "qp", "adaptive", "sweep", "iter3d"];

/// `Ok(None)`: no `--tables`, run criterion; `Err`: a message naming the argument.
fn parse_tables(args: &[String]) -> Result<Option<Tables>, String> {
    let (mut list, mut seconds, mut dump) = (None, None, None);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value =
            |name: &str| it.next().cloned().ok_or_else(|| format!("`{name}` needs a value"));
        match a.as_str() {
            "--tables" => list = Some(value("--tables")?),
            "--iter3d-seconds" => {
                let v = value("--iter3d-seconds")?;
                let s: f64 =
                    v.parse().ok().filter(|s: &f64| s.is_finite() && *s >= 0.0).ok_or_else(
                        || format!("`--iter3d-seconds {v}`: not a number of seconds ≥ 0"),
                    )?;
                seconds = Some(s);
            }
            "--iter3d-dump" => dump = Some(value("--iter3d-dump")?),
            _ => {}
        }
    }
    let Some(list) = list else {
        return match (seconds, dump) {
            (None, None) => Ok(None),
            _ => Err("`--iter3d-seconds` and `--iter3d-dump` go with `--tables iter3d`".into()),
        };
    };
    let mut which = Vec::new();
    for name in list.split(',').map(str::trim) {
        match TABLE_NAMES.iter().find(|t| **t == name) {
            Some(t) => which.push(*t),
            None if name == "all" => which.extend(TABLE_NAMES),
            None => {
                return Err(format!(
                    "`--tables {list}`: unknown table `{name}` (one of {}, all)",
                    TABLE_NAMES.join(", ")
                ))
            }
        }
    }
    which.sort_by_key(|w| TABLE_NAMES.iter().position(|t| t == w));
    which.dedup();
    Ok(Some(Tables { which, iter3d_seconds: seconds.unwrap_or(1.0), iter3d_dump: dump }))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--help" || a == "-h") && !args.iter().any(|a| a == "--tables") {
        println!("{USAGE}\n\ncriterion's arguments:");
    }
    let tables = match parse_tables(&args) {
        Ok(Some(t)) => t,
        Ok(None) => return benches(),
        Err(e) => {
            eprintln!("error: {e}\n\n{USAGE}");
            std::process::exit(2);
        }
    };
    for table in &tables.which {
        match *table {
            "int" => integrator_table(),
            "qp" => qp_table(),
            "adaptive" => adaptive_table(),
            "sweep" => sweep_table(),
            "iter3d" => iteration_3d_table(tables.iter3d_seconds, tables.iter3d_dump.as_deref()),
            _ => unreachable!("names come from TABLE_NAMES"),
        }
    }
}
