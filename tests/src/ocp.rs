//! Verification cases of the `ocp-transcription` crate (names `ocp-transcription/<case>`).

use crate::{Case, CaseOutcome, Metric, Tier};
use nalgebra::{DMatrix, DVector};
use ocp_transcription::samples::{self, seeded, CartPole, Fragile, LinearModel, ModalLike};
use ocp_transcription::{
    interval_error, AdaptiveSubsteps, Dynamics, Globalisation, HessianApproximation, Integrator,
    IntegratorKind, IntegratorSettings, Ocp, QpForm, SqpSettings, SqpSolver, SqpStatus,
};
use rand::Rng;

/// The cases of `ocp-transcription`.
pub fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "ocp-transcription/sensitivities-vs-finite-differences",
            tier: Tier::Quick,
            run: sensitivities,
        },
        Case { name: "ocp-transcription/integrator-orders", tier: Tier::Quick, run: orders },
        Case { name: "ocp-transcription/lq-equals-riccati", tier: Tier::Quick, run: lq_riccati },
        Case { name: "ocp-transcription/cartpole-swing-up", tier: Tier::Quick, run: swing_up },
        Case { name: "ocp-transcription/failure-statuses", tier: Tier::Quick, run: statuses },
        Case {
            name: "ocp-transcription/unstable-horizon-qp-accuracy",
            tier: Tier::Quick,
            run: unstable_horizon,
        },
        Case {
            name: "ocp-transcription/modal-like-closed-loop",
            tier: Tier::Quick,
            run: modal_closed_loop,
        },
        Case {
            name: "ocp-transcription/adaptive-substeps",
            tier: Tier::Quick,
            run: adaptive_substeps,
        },
    ]
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Max relative deviation of `A`, `B` from central differences (step 1e-6), three substeps
/// over 0.1.
fn fd_error<D: Dynamics>(
    model: &D,
    kind: IntegratorKind,
    x: &[f64],
    u: &[f64],
) -> Result<f64, String> {
    let mut int = Integrator::new(model, &IntegratorSettings::new(kind, 3), 0.1).map_err(err)?;
    samples::fd_sensitivity_error(&mut int, model, x, u).map_err(err)
}

fn sensitivities() -> CaseOutcome {
    let model = ModalLike::new(10, 2, 30.0, 1.0, 5).map_err(err)?;
    let mut rng = seeded(42);
    let mut out = Vec::new();
    for kind in [IntegratorKind::Rk4, IntegratorKind::ImplicitMidpoint, IntegratorKind::LawsonRk4] {
        let mut e = 0.0_f64;
        for _ in 0..16 {
            let x: Vec<f64> = (0..10).map(|_| rng.random_range(-1.0..1.0)).collect();
            let u: Vec<f64> = (0..2).map(|_| rng.random_range(-1.0..1.0)).collect();
            e = e.max(fd_error(&model, kind, &x, &u)?);
        }
        // central differences: truncation ~1e-12, round-off ~1e-10
        out.push(Metric::at_most(
            format!("{kind:?}: max rel. deviation of A, B from central FD"),
            e,
            1e-6,
        ));
    }
    // the ROM-structured sample: > 30 % nonzero Jacobian with the ROM's zero blocks, so the
    // block-range products (and their cached pattern) are exercised
    let rom = ModalLike::rom_like(24, 3, 60.0, 0.5, 5).map_err(err)?;
    let mut e = 0.0_f64;
    for _ in 0..8 {
        let x: Vec<f64> = (0..24).map(|_| rng.random_range(-0.5..0.5)).collect();
        let u: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
        e = e.max(fd_error(&rom, IntegratorKind::LawsonRk4, &x, &u)?);
    }
    out.push(Metric::at_most("LawsonRk4, ROM-structured nx = 24: max rel. deviation", e, 1e-6));
    Ok(out)
}

/// Observed order of the one-interval error against a fine Lawson reference.
fn orders() -> CaseOutcome {
    let model = ModalLike::new(21, 3, 60.0, 1.0, 9).map_err(err)?;
    let x: Vec<f64> = (0..21).map(|i| 0.4 * ((i as f64) * 0.7).sin()).collect();
    let u = [0.3, -0.2, 0.1];
    let dt = 0.25;
    let mut reference = vec![0.0; 21];
    let mut int =
        Integrator::new(&model, &IntegratorSettings::new(IntegratorKind::LawsonRk4, 2048), dt)
            .map_err(err)?;
    int.integrate(&model, &x, &u, &mut reference).map_err(err)?;
    let mut out = Vec::new();
    for (kind, n0, expected) in [
        (IntegratorKind::Rk4, 64, 4.0),
        (IntegratorKind::LawsonRk4, 16, 4.0),
        (IntegratorKind::ImplicitMidpoint, 64, 2.0),
    ] {
        let mut errs = Vec::new();
        for n in [n0, 2 * n0] {
            let mut int =
                Integrator::new(&model, &IntegratorSettings::new(kind, n), dt).map_err(err)?;
            let mut xe = vec![0.0; 21];
            int.integrate(&model, &x, &u, &mut xe).map_err(err)?;
            let e = xe.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            errs.push(e);
        }
        let order = (errs[0] / errs[1]).log2();
        // asymptotic regime: the observed order is within 0.3 of the method's order
        out.push(Metric::at_least(
            format!("{kind:?}: observed order (n = {n0} → {})", 2 * n0),
            order,
            expected - 0.3,
        ));
    }
    Ok(out)
}

fn lq_riccati() -> CaseOutcome {
    let model = LinearModel::spring_chain(3, 2);
    let mut ocp = Ocp::new(6, 2, 3.0, 15).map_err(err)?;
    ocp.r = DMatrix::identity(2, 2) * 0.5;
    ocp.terminal = DMatrix::identity(6, 6) * 2.0;
    let x0 = DVector::from_vec(vec![0.5, -0.3, 0.2, 0.0, 0.4, -0.1]);
    let (nx, nu, n, dt) = (6, 2, 15, ocp.interval());
    let settings = SqpSettings::default();
    let mut int = Integrator::new(&model, &settings.integrator, dt).map_err(err)?;
    let (mut a, mut b, mut xe) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu), vec![0.0; nx]);
    int.integrate_with_sensitivities(&model, &[0.0; 6], &[0.0; 2], &mut xe, &mut a, &mut b)
        .map_err(err)?;
    let rd = &ocp.r * dt;
    let mut p = &ocp.q * (0.5 * dt) + &ocp.terminal;
    let mut gains = vec![DMatrix::zeros(nu, nx); n];
    for k in (0..n).rev() {
        let btp = b.transpose() * &p;
        let gain = (&rd + &btp * &b).cholesky().ok_or("Riccati: not PD")?.solve(&(&btp * &a));
        let qk = &ocp.q * if k == 0 { 0.5 * dt } else { dt };
        p = qk + a.transpose() * &p * (&a - &b * &gain);
        p = 0.5 * (&p + p.transpose());
        gains[k] = gain;
    }
    let mut out = Vec::new();
    for form in [QpForm::CondensedDense, QpForm::CondensedClarabel, QpForm::SparseClarabel] {
        let mut solver = SqpSolver::new(
            &model,
            ocp.clone(),
            SqpSettings { qp_form: form, ..SqpSettings::default() },
        )
        .map_err(err)?;
        let stats = solver.solve(x0.as_slice()).map_err(err)?;
        if stats.status != SqpStatus::Solved {
            return Err(format!("{form:?}: status {:?}", stats.status));
        }
        let mut x = x0.clone();
        let mut dev = 0.0_f64;
        for k in 0..n {
            let u = -&gains[k] * &x;
            x = &a * &x + &b * &u;
            dev = dev
                .max((&solver.controls()[k] - &u).amax())
                .max((&solver.states()[k + 1] - &x).amax());
        }
        out.push(Metric::at_most(format!("{form:?}: max |SQP − Riccati|"), dev, 1e-8));
        out.push(Metric::at_most(
            format!("{form:?}: SQP iterations"),
            stats.iterations as f64,
            1.0,
        ));
    }
    Ok(out)
}

fn swing_up_ocp() -> Result<Ocp, String> {
    let mut ocp = Ocp::new(4, 1, 1.5, 30).map_err(err)?;
    ocp.q = DMatrix::from_diagonal(&DVector::from_vec(vec![10.0, 10.0, 0.1, 0.1]));
    ocp.r = DMatrix::identity(1, 1) * 1e-3;
    ocp.terminal = DMatrix::from_diagonal(&DVector::from_vec(vec![100.0, 100.0, 10.0, 10.0]));
    ocp.u_min[0] = -25.0;
    ocp.u_max[0] = 25.0;
    Ok(ocp)
}

fn swing_up() -> CaseOutcome {
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let mut out = Vec::new();
    for hessian in [HessianApproximation::GaussNewton, HessianApproximation::Exact] {
        let settings = SqpSettings {
            hessian,
            max_iterations: 100,
            integrator: IntegratorSettings::new(IntegratorKind::Rk4, 2),
            ..SqpSettings::default()
        };
        let mut solver =
            SqpSolver::new(CartPole::default(), swing_up_ocp()?, settings).map_err(err)?;
        solver.initialize_constant(&x0, &[0.0]).map_err(err)?;
        let stats = solver.solve(&x0).map_err(err)?;
        if stats.status != SqpStatus::Solved {
            return Err(format!("{hessian:?}: status {:?}", stats.status));
        }
        out.push(Metric::at_most(format!("{hessian:?}: final KKT residual"), stats.kkt, 1e-8));
        let active = solver.controls().iter().filter(|u| (u[0].abs() - 25.0).abs() < 1e-9).count();
        out.push(Metric::at_least(
            format!("{hessian:?}: controls at the bound |F| = 25"),
            active as f64,
            2.0,
        ));
        out.push(Metric::at_most(
            format!("{hessian:?}: |θ(τp)| (upright)"),
            solver.states()[30][1].abs(),
            0.2,
        ));
        if hessian == HessianApproximation::Exact {
            let mut e: Vec<f64> = solver.log().iter().map(|l| l.kkt).collect();
            e.push(stats.kkt);
            let m = e.len();
            let c = (e[m - 1] / (e[m - 2] * e[m - 2])).max(e[m - 2] / (e[m - 3] * e[m - 3]));
            out.push(Metric::at_most(
                "Exact: max e⁺/e² over the last two iterations (quadratic)",
                c,
                10.0,
            ));
            out.push(Metric::at_most(
                "Exact: SQP iterations from cold start",
                stats.iterations as f64,
                45.0,
            ));
        } else {
            out.push(Metric::at_most(
                "GaussNewton: SQP iterations from cold start",
                stats.iterations as f64,
                80.0,
            ));
        }
    }
    Ok(out)
}

fn statuses() -> CaseOutcome {
    let x0 = [0.0, std::f64::consts::PI, 0.0, 0.0];
    let ocp = swing_up_ocp()?;
    let flag = |ok: bool| if ok { 1.0 } else { 0.0 };
    let mut out = Vec::new();
    let settings = SqpSettings { globalisation: Globalisation::FullStep, ..SqpSettings::default() };
    let mut s = SqpSolver::new(Fragile(CartPole::default()), ocp.clone(), settings).map_err(err)?;
    s.initialize_constant(&[0.6, 3.0, 0.0, 0.0], &[0.0]).map_err(err)?;
    let st = s.solve(&x0).map_err(err)?.status;
    out.push(Metric::at_least(
        "NaN dynamics → NonFiniteDynamics",
        flag(st == SqpStatus::NonFiniteDynamics),
        1.0,
    ));
    let mut s = SqpSolver::new(
        CartPole::default(),
        ocp.clone(),
        SqpSettings { max_iterations: 3, ..SqpSettings::default() },
    )
    .map_err(err)?;
    s.initialize_constant(&x0, &[0.0]).map_err(err)?;
    let st = s.solve(&x0).map_err(err)?.status;
    out.push(Metric::at_least(
        "3 iterations → MaxIterations",
        flag(st == SqpStatus::MaxIterations),
        1.0,
    ));
    let mut bad = ocp;
    bad.x_min[0] = 10.0;
    for form in [QpForm::CondensedClarabel, QpForm::SparseClarabel] {
        let mut s = SqpSolver::new(
            CartPole::default(),
            bad.clone(),
            SqpSettings { qp_form: form, ..SqpSettings::default() },
        )
        .map_err(err)?;
        s.initialize_constant(&x0, &[0.0]).map_err(err)?;
        let st = s.solve(&x0).map_err(err)?.status;
        out.push(Metric::at_least(
            format!("{form:?}: unreachable state bound → QpInfeasible"),
            flag(st == SqpStatus::QpInfeasible),
            1.0,
        ));
    }
    Ok(out)
}

/// States `x_0 … x_N` and controls `u_0 … u_{N−1}`.
type Trajectory = (Vec<DVector<f64>>, Vec<DVector<f64>>);

/// Riccati (closed-loop) solution of the discrete LQ problem the SQP builds for `model`.
fn riccati_solution(
    model: &LinearModel,
    ocp: &Ocp,
    settings: &IntegratorSettings,
    x0: &DVector<f64>,
) -> Result<Trajectory, String> {
    let (nx, nu, n, dt) = (ocp.nx(), ocp.nu(), ocp.intervals, ocp.interval());
    let mut int = Integrator::new(model, settings, dt).map_err(err)?;
    let (mut a, mut b, mut xe) = (DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu), vec![0.0; nx]);
    int.integrate_with_sensitivities(
        model,
        &vec![0.0; nx],
        &vec![0.0; nu],
        &mut xe,
        &mut a,
        &mut b,
    )
    .map_err(err)?;
    let rd = &ocp.r * dt;
    let mut p = &ocp.q * (0.5 * dt) + &ocp.terminal;
    let mut gains = vec![DMatrix::zeros(nu, nx); n];
    for k in (0..n).rev() {
        let btp = b.transpose() * &p;
        let gain = (&rd + &btp * &b).cholesky().ok_or("Riccati: not PD")?.solve(&(&btp * &a));
        let qk = &ocp.q * if k == 0 { 0.5 * dt } else { dt };
        p = qk + a.transpose() * &p * (&a - &b * &gain);
        p = 0.5 * (&p + p.transpose());
        gains[k] = gain;
    }
    let mut xs = vec![x0.clone()];
    let mut us = Vec::new();
    for k in 0..n {
        let u = -&gains[k] * &xs[k];
        xs.push(&a * &xs[k] + &b * &u);
        us.push(u);
    }
    Ok((xs, us))
}

/// Three inverted pendula (`ẍ = a x + u`, growth `e^{√a τp}` ≈ 1e7 over the 6 s horizon, as
/// the modal problem near ω0 = 2): condensed and sparse QPs against the Riccati solution.
fn unstable_horizon() -> CaseOutcome {
    let (m, a_coef) = (3, (1e7_f64.ln() / 6.0).powi(2));
    let nx = 2 * m;
    let mut am = DMatrix::zeros(nx, nx);
    let mut bm = DMatrix::zeros(nx, m);
    for i in 0..m {
        am[(i, m + i)] = 1.0;
        am[(m + i, i)] = a_coef * (1.0 + 0.1 * i as f64);
        bm[(m + i, i)] = 1.0;
    }
    let model = LinearModel::new(am, bm).map_err(err)?;
    let mut ocp = Ocp::new(nx, m, 6.0, 24).map_err(err)?;
    ocp.r = DMatrix::identity(m, m) * 0.1;
    let x0 = DVector::from_fn(nx, |i, _| 0.1 * (i as f64 + 1.0).sin());
    let settings = IntegratorSettings::new(IntegratorKind::Rk4, 8);
    let (xs, us) = riccati_solution(&model, &ocp, &settings, &x0)?;
    let scale = us.iter().map(|u| u.amax()).fold(0.0, f64::max);
    let mut out = Vec::new();
    for form in
        [QpForm::Auto, QpForm::CondensedDense, QpForm::CondensedClarabel, QpForm::SparseClarabel]
    {
        let s = SqpSettings {
            qp_form: form,
            integrator: settings.clone(),
            max_iterations: 3,
            ..SqpSettings::default()
        };
        let mut solver = SqpSolver::new(&model, ocp.clone(), s).map_err(err)?;
        let stats = solver.solve(x0.as_slice()).map_err(err)?;
        let mut dev = 0.0_f64;
        for k in 0..ocp.intervals {
            dev = dev.max((&solver.controls()[k] - &us[k]).amax());
            dev = dev.max((&solver.states()[k + 1] - &xs[k + 1]).amax());
        }
        let rel = dev / scale;
        match form {
            // the multiple-shooting QP never forms the ill-conditioned condensed Hessian;
            // Auto detects the conditioning and switches to it
            QpForm::SparseClarabel | QpForm::Auto => out.push(Metric::at_most(
                format!("{form:?}: max |w − w_Riccati| / max|u|"),
                rel,
                1e-10,
            )),
            // condensing costs digits (condition ~1e14): reported, bounded loosely
            QpForm::CondensedDense => out.push(Metric::at_most(
                format!("{form:?}: max |w − w_Riccati| / max|u|"),
                rel,
                1e-6,
            )),
            // Clarabel may give up on the condensed QP: it must say so, not return garbage
            _ => {
                let honest = stats.status == SqpStatus::QpFailed
                    || (stats.status == SqpStatus::Solved && rel < 1e-6);
                out.push(Metric::at_least(
                    format!(
                        "{form:?}: accurate or QpFailed (status {:?}, rel. dev. {rel:.1e})",
                        stats.status
                    ),
                    if honest { 1.0 } else { 0.0 },
                    1.0,
                ));
            }
        }
    }
    Ok(out)
}

/// Closed loop on a model with the modal ROM's structure (nx = 21, ω ≤ 60 rad/s): NMPC with
/// Lawson RK4 × 8 per 0.25 s interval, warm start by `shift_time(τs = 0.2 s)` (not a multiple
/// of Δt), plant = the same model integrated by Lawson × 64.
fn modal_closed_loop() -> CaseOutcome {
    let model = ModalLike::new(21, 3, 60.0, 1.0, 9).map_err(err)?;
    let mut ocp = Ocp::new(21, 3, 3.0, 12).map_err(err)?;
    ocp.r = DMatrix::identity(3, 3) * 0.1;
    ocp.u_min = DVector::from_element(3, -5.0);
    ocp.u_max = DVector::from_element(3, 5.0);
    let settings = SqpSettings {
        integrator: IntegratorSettings::new(IntegratorKind::LawsonRk4, 8),
        max_iterations: 30,
        ..SqpSettings::default()
    };
    let mut solver = SqpSolver::new(&model, ocp, settings).map_err(err)?;
    let mut plant =
        Integrator::new(&model, &IntegratorSettings::new(IntegratorKind::LawsonRk4, 64), 0.2)
            .map_err(err)?;
    let mut x: Vec<f64> = (0..21).map(|i| 0.5 * ((i as f64) * 1.7).cos()).collect();
    let energy = |x: &[f64]| 0.5 * x.iter().map(|v| v * v).sum::<f64>();
    let e0 = energy(&x);
    solver.initialize_constant(&x, &[0.0; 3]).map_err(err)?;
    let mut solved = 0;
    let mut max_iter = 0;
    let samples = 25;
    for _ in 0..samples {
        let st = solver.solve(&x).map_err(err)?;
        solved += (st.status == SqpStatus::Solved) as usize;
        max_iter = max_iter.max(st.iterations);
        let u: Vec<f64> = solver.first_control().iter().copied().collect();
        let mut next = vec![0.0; 21];
        plant.integrate(&model, &x, &u, &mut next).map_err(err)?;
        x = next;
        solver.shift_time(0.2).map_err(err)?;
    }
    // the same plant without control, for comparison
    let mut xf: Vec<f64> = (0..21).map(|i| 0.5 * ((i as f64) * 1.7).cos()).collect();
    for _ in 0..samples {
        let mut next = vec![0.0; 21];
        plant.integrate(&model, &xf, &[0.0; 3], &mut next).map_err(err)?;
        xf = next;
    }
    let ratio = energy(&x) / e0;
    let free = energy(&xf) / e0;
    Ok(vec![
        Metric::at_least("samples whose NLP reached KKT ≤ 1e-8", solved as f64, samples as f64),
        Metric::at_most(
            format!("½|x|² after 5 s / initial (uncontrolled: {free:.3})"),
            ratio,
            0.25,
        ),
        Metric::at_most("controlled / uncontrolled energy after 5 s", ratio / free, 0.35),
        Metric::at_most("max SQP iterations per warm-started sample", max_iter as f64, 15.0),
    ])
}

/// State-adapted substep counts with the documented default table (tolerance 1e-3) on the
/// paper-sized ROM-like model: one-interval errors at 32 random states (rotation rate in
/// [0, 2.2], random elastic content ≤ 0.1, inputs in [−5, 5]) against Lawson × 512, the
/// spread of the chosen counts, and a full SQP with adapted counts on a 21-state ROM-like OCP
/// reaching the KKT tolerance.
fn adaptive_substeps() -> CaseOutcome {
    let m = ModalLike::paper_sized_rom();
    let nx = m.nx();
    let table = AdaptiveSubsteps::default();
    let settings = IntegratorSettings {
        adaptive: Some(table.clone()),
        ..IntegratorSettings::new(IntegratorKind::LawsonRk4, 16)
    };
    let mut int = Integrator::new(&m, &settings, 0.25).map_err(err)?;
    let mut reference =
        Integrator::new(&m, &IntegratorSettings::new(IntegratorKind::LawsonRk4, 512), 0.25)
            .map_err(err)?;
    let mut rng = seeded(2026);
    let (mut xr, mut xe) = (vec![0.0; nx], vec![0.0; nx]);
    let (mut worst, mut lo, mut hi, mut total) = (0.0_f64, usize::MAX, 0usize, 0usize);
    let samples = 32;
    for _ in 0..samples {
        let mut x = m.rotating_state(rng.random_range(0.0..2.2)).ok_or("rom-like model")?;
        let amp = rng.random_range(0.0..0.1);
        for v in x.iter_mut().skip(2) {
            *v += amp * rng.random_range(-1.0..1.0);
        }
        let u: Vec<f64> = (0..5).map(|_| rng.random_range(-5.0..5.0)).collect();
        reference.integrate(&m, &x, &u, &mut xr).map_err(err)?;
        let n = int.choose_substeps(&m, &x, &u, Some(&xr));
        int.set_substeps(n).map_err(err)?;
        int.integrate(&m, &x, &u, &mut xe).map_err(err)?;
        worst = worst.max(interval_error(&xe, &xr));
        lo = lo.min(n);
        hi = hi.max(n);
        total += n;
    }
    let small = ModalLike::rom_like(21, 3, 120.0, 0.1, 7).map_err(err)?;
    let mut ocp = Ocp::new(21, 3, 1.5, 6).map_err(err)?;
    ocp.r = DMatrix::identity(3, 3) * 0.1;
    ocp.u_min = DVector::from_element(3, -5.0);
    ocp.u_max = DVector::from_element(3, 5.0);
    let (mm, nq2, _) = small.rom_blocks().ok_or("rom-like model")?;
    ocp.x_ref[mm + nq2] = 1.0;
    let sqp = SqpSettings {
        qp_form: QpForm::CondensedDense,
        globalisation: Globalisation::FullStep,
        integrator: IntegratorSettings {
            adaptive: Some(AdaptiveSubsteps { min_substeps: 4, max_substeps: 40, ..table }),
            ..IntegratorSettings::new(IntegratorKind::LawsonRk4, 4)
        },
        ..SqpSettings::default()
    };
    let x0 = small.rotating_state(0.5).ok_or("rom-like model")?;
    let mut solver = SqpSolver::new(&small, ocp, sqp).map_err(err)?;
    solver.initialize_by_simulation(&x0, &[0.0; 3]).map_err(err)?;
    let st = solver.solve(&x0).map_err(err)?;
    Ok(vec![
        Metric::at_most(
            format!(
                "max one-interval error, adapted counts (mean {:.1}, {lo}–{hi})",
                total as f64 / samples as f64
            ),
            worst,
            1e-3,
        ),
        Metric::at_least("spread of the chosen counts (max − min)", (hi - lo) as f64, 4.0),
        Metric::at_most(
            format!(
                "SQP with adapted counts: KKT ({:?}, mean substeps {:.1})",
                st.status, st.mean_substeps
            ),
            st.kkt,
            1e-8,
        ),
    ])
}
