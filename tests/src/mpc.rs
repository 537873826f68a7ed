//! Verification cases of the `mpc` crate (names `mpc/<case>`): closed loops of the paper's
//! 2D and 3D two-links (§5.2–5.3) against the stabilisation criterion of docs/mpc.md, solve times,
//! and reproducibility.

use crate::{Case, CaseOutcome, Metric, Tier};
use mpc::{
    run, sweep, ControllerKind, ControllerSettings, PlantKind, RunSummary, Scenario, Setup,
    Strategy,
};

/// The cases of `mpc`.
pub fn cases() -> Vec<Case> {
    vec![
        Case { name: "mpc/2d-nmpc-fe-short", tier: Tier::Quick, run: nmpc_short },
        Case { name: "mpc/2d-lmpc-rom-determinism", tier: Tier::Quick, run: determinism },
        Case { name: "mpc/2d-nmpc-fe-safeguards", tier: Tier::Quick, run: nmpc_safeguards },
        Case { name: "mpc/2d-sweep-lmpc-fe", tier: Tier::Full, run: sweep_2d_lmpc },
        Case { name: "mpc/2d-sweep-nmpc-fe", tier: Tier::Full, run: sweep_2d_nmpc },
        Case { name: "mpc/2d-sweep-nmpc-rom", tier: Tier::Full, run: sweep_2d_nmpc_rom },
        Case { name: "mpc/3d-sweep-nmpc-fe", tier: Tier::Full, run: sweep_3d_nmpc },
        Case { name: "mpc/3d-sweep-lmpc-fe", tier: Tier::Full, run: sweep_3d_lmpc },
        Case { name: "mpc/3d-stabilisation", tier: Tier::Full, run: stabilisation_3d },
        Case { name: "mpc/3d-exact-joints", tier: Tier::Full, run: exact_joints_3d },
        Case {
            name: "mpc/3d-exact-joints-full-range",
            tier: Tier::Full,
            run: exact_joints_3d_full_range,
        },
        Case { name: "mpc/real-time", tier: Tier::Full, run: real_time },
    ]
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// The paper's mesh: 2 × 50 elements.
const ELEMENTS: usize = 50;

/// Two seconds of NMPC on the paper's 2D FE plant at ω0 = 0.5: every sample solved by the
/// first SQP attempt, the rotation slowed down, the joint within the model's range (the modes
/// are computed at 0°), the inputs within their bounds.
fn nmpc_short() -> CaseOutcome {
    let mut sc = Scenario::paper_2d(ELEMENTS).map_err(err)?;
    sc.duration = 2.0;
    let setup = Setup::new(&sc).map_err(err)?;
    let r = run(&setup, 0.5, &ControllerSettings::full_sqp(), PlantKind::Fe).map_err(err)?;
    if let Some(e) = &r.summary.error {
        return Err(e.clone());
    }
    let failed = r.samples.iter().filter(|s| s.strategy != Strategy::Sqp).count();
    let umax = r.records.iter().flat_map(|x| x.u.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    Ok(vec![
        Metric::at_most("samples not solved by the first SQP attempt", failed as f64, 0.0),
        // without control the rigid rate stays at ω0 (ratio 1)
        Metric::at_most("rigid rate ratio at t = 2 s", r.summary.rigid_rate_ratio, 0.5),
        Metric::at_most("max joint angle (deg)", r.summary.max_joint_angle_deg, 30.0),
        Metric::at_most("max abs(u) (bound 5)", umax, 5.0),
    ])
}

/// The NMPC's model-validity safeguards at the largest disturbance of the 2D sweep
/// (ω0 = 2, paper mesh, FE plant, first 1.6 s): the first plans drive the elbow beyond
/// `plan_joint_limit_deg` (20°) or fail, so the LMPC plan is applied and held; the elbow of
/// the FE plant stays where the linear MPC alone keeps it (measured 34.5° over the whole
/// run; without the safeguards the NMPC took it to 240°, docs/mpc.md), the inputs in bounds.
fn nmpc_safeguards() -> CaseOutcome {
    let mut sc = Scenario::paper_2d(ELEMENTS).map_err(err)?;
    sc.duration = 1.6;
    let setup = Setup::new(&sc).map_err(err)?;
    let r = run(&setup, 2.0, &ControllerSettings::full_sqp(), PlantKind::Fe).map_err(err)?;
    if let Some(e) = &r.summary.error {
        return Err(e.clone());
    }
    let s = &r.summary;
    let umax = r.records.iter().flat_map(|x| x.u.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    Ok(vec![
        Metric::at_least(
            "samples with a plan beyond the joint limit",
            s.joint_limit_samples as f64,
            1.0,
        ),
        Metric::at_least("samples held on the LMPC plan", s.held_samples as f64, 1.0),
        Metric::at_most("max elbow angle of the FE plant (deg)", s.max_joint_angle_deg, 40.0),
        Metric::at_most("max abs(u) (bound 5)", umax, 5.0),
    ])
}

/// Two identical 7.5 s runs (LMPC on the ROM plant, paper mesh) give identical results
/// (wall-clock timings aside).
fn determinism() -> CaseOutcome {
    let setup = Setup::new(&Scenario::paper_2d(ELEMENTS).map_err(err)?).map_err(err)?;
    let c = ControllerSettings::of(ControllerKind::Lmpc);
    let a = run(&setup, 1.0, &c, PlantKind::Rom).map_err(err)?.without_timings();
    let b = run(&setup, 1.0, &c, PlantKind::Rom).map_err(err)?.without_timings();
    let mut diff = 0.0f64;
    for (x, y) in a.records.iter().zip(&b.records) {
        for (p, q) in x.q.iter().zip(&y.q).chain(x.u.iter().zip(&y.u)) {
            diff = diff.max((p - q).abs());
        }
    }
    let same = if a == b { 0.0 } else { 1.0 };
    Ok(vec![
        Metric::at_most("max abs difference of states and inputs", diff, 0.0),
        Metric::at_most("results differ (0/1)", same, 0.0),
    ])
}

/// The criterion per run, as three metrics, plus NMPC's use of the fallbacks.
fn criterion(s: &RunSummary, out: &mut Vec<Metric>) {
    let w = s.omega0;
    if let Some(e) = &s.error {
        out.push(Metric::at_most(format!("ω0={w}: run stopped at t={} ({e})", s.t_end), 1.0, 0.0));
        return;
    }
    out.push(Metric::at_most(format!("ω0={w}: V(7.5)/V(0)"), s.v_ratio_final, 0.1));
    out.push(Metric::at_most(format!("ω0={w}: rigid rate / ω0"), s.rigid_rate_ratio, 0.05));
    out.push(Metric::at_most(
        format!("ω0={w}: orientation error / largest excursion"),
        s.orientation_error_deg / s.max_orientation_deg.max(1e-300),
        0.2,
    ));
    out.push(Metric::at_most(
        format!("ω0={w}: largest elbow angle (deg, report)"),
        s.max_joint_angle_deg,
        f64::INFINITY,
    ));
    if s.controller == "nmpc" {
        for (what, n) in [
            ("relaxed retry", s.relaxed_samples),
            ("LMPC fallback", s.fallback_samples),
            ("LMPC held after a fallback", s.held_samples),
            ("plan beyond the joint limit", s.joint_limit_samples),
        ] {
            out.push(Metric::at_most(
                format!("ω0={w}: samples with {what} (report)"),
                n as f64,
                f64::INFINITY,
            ));
        }
    }
}

fn sweep_case(three_d: bool, kind: ControllerKind, omegas: &[f64], time_goal: bool) -> CaseOutcome {
    sweep_case_on(three_d, kind, omegas, time_goal, PlantKind::Fe)
}

fn sweep_case_on(
    three_d: bool,
    kind: ControllerKind,
    omegas: &[f64],
    time_goal: bool,
    plant: PlantKind,
) -> CaseOutcome {
    let mut c = ControllerSettings { kind, ..ControllerSettings::full_sqp() };
    if plant == PlantKind::Rom {
        // the joint-angle limit guards against the FE plant leaving the range where the
        // 0°-mode model predicts it; with the model itself as the plant there is no such
        // range (measured: with the limit the LMPC fallback costs ω0 = 2, orientation 23%)
        c.plan_joint_limit_deg = None;
    }
    let sc = if three_d { Scenario::paper_3d(ELEMENTS) } else { Scenario::paper_2d(ELEMENTS) }
        .map_err(err)?;
    let setup = Setup::new(&sc).map_err(err)?;
    let results = sweep(&setup, omegas, &c, plant, &|| {});
    let mut out = Vec::new();
    let mut worst = 0.0f64;
    let mut wall = 0.0f64;
    for r in results {
        let r = r.map_err(err)?;
        criterion(&r.summary, &mut out);
        worst = worst.max(r.summary.solve_time_worst_s);
        wall = wall.max(r.wall_time_s);
    }
    if time_goal {
        // real-time goal: worst sample under 50 ms (4× under τs = 0.2 s); whole loop under 10 s
        out.push(Metric::at_most("worst per-sample solve time (s)", worst, 0.05));
        out.push(Metric::at_most("slowest closed loop wall time (s)", wall, 10.0));
    }
    Ok(out)
}

const OMEGAS_2D: [f64; 8] = [0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0];

fn sweep_2d_lmpc() -> CaseOutcome {
    sweep_case(false, ControllerKind::Lmpc, &OMEGAS_2D, false)
}

// The library default (full SQP ≤ 10 iterations + relaxed retry) is checked for the
// criterion; the real-time goal (50 ms per sample) is checked on the real-time configuration of
// the shipped scenes by `mpc/real-time`, and the full SQP's times are in docs/mpc.md.
fn sweep_2d_nmpc() -> CaseOutcome {
    sweep_case(false, ControllerKind::Nmpc, &OMEGAS_2D, false)
}

/// The NMPC with the modal model itself as the plant (no model mismatch): separates the
/// controller (sampling, control grid, SQP) from the FE plant / model mismatch; without the
/// joint-angle limit, which is about that mismatch.
fn sweep_2d_nmpc_rom() -> CaseOutcome {
    sweep_case_on(false, ControllerKind::Nmpc, &OMEGAS_2D, false, PlantKind::Rom)
}

/// The library default (full SQP, paper weights) in 3D, where it holds (ω0 ≤ 0.75); at
/// ω0 = 1.0 it does not, which `mpc/3d-stabilisation` reports next to the real-time spatial NMPC
/// with the `k_u` option that does.
fn sweep_3d_nmpc() -> CaseOutcome {
    sweep_case(true, ControllerKind::Nmpc, &[0.25, 0.5, 0.75], false)
}

/// The paper's 3D scenario with the documented input-weight option `k_u` =
/// [`mpc::SPATIAL_INPUT_WEIGHT`] (`scenes/paper-3d-mpc-ku1.toml`).
fn setup_3d_ku_option() -> Result<Setup, String> {
    let mut sc = Scenario::paper_3d(ELEMENTS).map_err(err)?;
    sc.mpc.cost.ku = mpc::SPATIAL_INPUT_WEIGHT;
    Setup::new(&sc).map_err(err)
}

/// The 3D LMPC where it is expected to hold (ω0 = 0.25); where it fails as ω0 grows is
/// the report of `mpc/3d-stabilisation`, not a criterion to pass.
fn sweep_3d_lmpc() -> CaseOutcome {
    sweep_case(true, ControllerKind::Lmpc, &[0.25], false)
}

/// The 3D stabilisation study as one case (3D two-link of §5.3 on the FE plant, the mpc
/// criterion at t = 7.5 s): the real-time spatial NMPC (`ControllerSettings::
/// real_time_spatial`) with the documented `k_u` option stabilises every ω0 = 0.25, 0.375, …,
/// 1.0; with the paper's weights (reported, not asserted) the library default and the same
/// real-time NMPC miss ω0 = 1.0. The LMPC (paper weights), which stabilises at 0.25, fails as
/// ω0 grows, the paper saw it fail between 0.5 and 0.75. Reports the smallest ω0 ≥ 0.5 at
/// which the LMPC misses the criterion and the smallest at which it loses the structure
/// (largest elbow angle beyond 90°, as Fig. 10's "chaotic control law").
fn stabilisation_3d() -> CaseOutcome {
    const NMPC: [f64; 7] = [0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0];
    const LMPC: [f64; 6] = [0.25, 0.5, 0.625, 0.75, 0.875, 1.0];
    let paper = Setup::new(&Scenario::paper_3d(ELEMENTS).map_err(err)?).map_err(err)?;
    let option = setup_3d_ku_option()?;
    let runs = |setup: &Setup, c: &ControllerSettings, omegas: &[f64]| -> Result<Vec<_>, String> {
        sweep(setup, omegas, c, PlantKind::Fe, &|| {})
            .into_iter()
            .map(|r| {
                let r = r.map_err(err)?;
                let chord = mpc::chord_orientation(&r.snapshots, 0).map_err(err)?;
                Ok((r.summary, chord))
            })
            .collect()
    };
    let spatial = ControllerSettings::real_time_spatial();
    let nmpc = runs(&option, &spatial, &NMPC)?;
    let lmpc = runs(&paper, &ControllerSettings::of(ControllerKind::Lmpc), &LMPC)?;
    let mut out = Vec::new();
    for (s, chord) in &nmpc {
        let w = s.omega0;
        out.push(Metric::at_least(
            format!("NMPC (k_u option) ω0={w}: stabilised (1) or not (0)"),
            f64::from(u8::from(s.stabilised)),
            1.0,
        ));
        out.push(Metric::at_most(
            format!("NMPC (k_u option) ω0={w}: largest elbow angle (deg, report)"),
            s.max_joint_angle_deg,
            f64::INFINITY,
        ));
        out.push(Metric::at_most(
            format!("NMPC (k_u option) ω0={w}: samples whose iteration failed (report)"),
            s.failed_first_attempts as f64,
            f64::INFINITY,
        ));
        // the root link's chord instead of its root node (docs/mpc.md: the node angle
        // includes the bending slope the root moments themselves cause)
        out.push(Metric::at_most(
            format!(
                "NMPC (k_u option) ω0={w}: chord orientation error / largest excursion (report)"
            ),
            chord.final_deg / chord.max_deg.max(1e-300),
            f64::INFINITY,
        ));
    }
    // the paper's weights at ω0 = 1.0, reported: what the option is for
    for (what, c) in [("full SQP", ControllerSettings::full_sqp()), ("real-time spatial", spatial)]
    {
        for (s, _) in runs(&paper, &c, &[1.0])? {
            out.push(Metric::at_most(
                format!("NMPC (paper k_u, {what}) ω0=1: stabilised (1) or not (0) (report)"),
                f64::from(u8::from(s.stabilised)),
                f64::INFINITY,
            ));
            out.push(Metric::at_most(
                format!("NMPC (paper k_u, {what}) ω0=1: largest elbow angle (deg, report)"),
                s.max_joint_angle_deg,
                f64::INFINITY,
            ));
        }
    }
    let lmpc: Vec<RunSummary> = lmpc.into_iter().map(|(s, _)| s).collect();
    // the paper: the LMPC "degrades and fails as ω0 grows" — it must hold at the smallest
    // disturbance and fail by 0.75 (the paper: between 0.5 and 0.75; here it misses the
    // orientation limit at 0.5 by 0.6 points, docs/mpc.md)
    out.push(Metric::at_least(
        "LMPC ω0=0.25: stabilised (1) or not (0)",
        f64::from(u8::from(lmpc[0].stabilised)),
        1.0,
    ));
    let first = |f: &dyn Fn(&RunSummary) -> bool| {
        lmpc.iter().find(|s| f(s)).map_or(f64::INFINITY, |s| s.omega0)
    };
    let misses = first(&|s| !s.stabilised);
    out.push(Metric::at_least("LMPC: smallest ω0 missing the criterion (report)", misses, 0.0));
    let lost = first(&|s| s.max_joint_angle_deg > 90.0 || s.error.is_some());
    out.push(Metric::at_most(
        "LMPC: fails by ω0 = 0.75 (smallest ω0 missing the criterion)",
        misses,
        0.75,
    ));
    out.push(Metric::at_most("LMPC: smallest ω0 losing the structure (elbow > 90°)", lost, 1.0));
    Ok(out)
}

/// The exact-joints NMPC of `scenes/paper-3d-mpc.toml` as the scene sets it up (real-time
/// iteration with the merit line search and a Levenberg–Marquardt term, no linear MPC
/// fallback, no plan joint-angle limit, paper weights `k_u = 0.1`, implicit-midpoint shooting
/// intervals with 4 substeps) on the paper's 3D two-link: the criterion at the largest ω0 of
/// the scene's sweep that it meets on the FE plant and on the ROM plant (the exact-joints model
/// itself as the plant). Also reports the samples whose SQP was not accepted, the largest
/// elbow angle and the worst / median per-sample solve time (CPU per thread; the scene's claim
/// is that it stays within τs = 0.2 s).
fn exact_joints_3d() -> CaseOutcome {
    let text = include_str!("../../scenes/paper-3d-mpc.toml");
    exact_joints_3d_scene("paper-3d-mpc.toml", text, EXACT_JOINTS_3D_OMEGAS)
}

/// The largest ω0 per plant with `scenes/paper-3d-mpc-full-range.toml` (the full SQP, up to 20
/// iterations per sample with a Levenberg–Marquardt term, on 24 elastic modes per link,
/// implicit midpoint × 8, a 5 s horizon of 20 intervals, 40 more SQP iterations on the first
/// sample, the later samples' first two intervals re-simulated from the measured state;
/// docs/mpc.md, "Unit rotations": ✓ FE and ROM 0.25…1.5), the same assertions as
/// `mpc/3d-exact-joints`. Two loops, ≈ 5 min CPU.
fn exact_joints_3d_full_range() -> CaseOutcome {
    let text = include_str!("../../scenes/paper-3d-mpc-full-range.toml");
    let omegas: &[(PlantKind, &[f64])] = &[(PlantKind::Fe, &[1.5]), (PlantKind::Rom, &[1.5])];
    exact_joints_3d_scene("paper-3d-mpc-full-range.toml", text, omegas)
}

/// Closed loops of a 3D exact-joints scene at `omegas` per plant: the criterion and
/// `V(7.5)/V(0)` asserted, samples not accepted, elbow angle, solve times and the model
/// evaluations per sample reported.
fn exact_joints_3d_scene(name: &str, text: &str, omegas: &[(PlantKind, &[f64])]) -> CaseOutcome {
    let scene = flexmpc::scene::load_str(std::path::Path::new(name), text).map_err(err)?;
    let control = scene.control.as_ref().ok_or("the scene has no [scenario]")?;
    let setup = Setup::new(&control.scenario).map_err(err)?;
    let c = &control.controller;
    let mut out = Vec::new();
    for (plant, omegas) in omegas {
        let name = match plant {
            PlantKind::Fe => "FE",
            PlantKind::Rom => "ROM",
        };
        for r in sweep(&setup, omegas, c, *plant, &|| {}) {
            let r = r.map_err(err)?;
            let s = &r.summary;
            let w = s.omega0;
            if let Some(e) = &s.error {
                return Err(format!("{name} plant ω0={w}: run stopped at t = {}: {e}", s.t_end));
            }
            out.push(Metric::at_least(
                format!("{name} plant ω0={w}: stabilised (1) or not (0)"),
                f64::from(u8::from(s.stabilised)),
                1.0,
            ));
            out.push(Metric::at_most(
                format!("{name} plant ω0={w}: V(7.5)/V(0)"),
                s.v_ratio_final,
                0.1,
            ));
            out.push(Metric::at_most(
                format!("{name} plant ω0={w}: samples whose SQP was not accepted (report)"),
                s.fallback_samples as f64,
                f64::INFINITY,
            ));
            out.push(Metric::at_most(
                format!("{name} plant ω0={w}: largest elbow angle (deg, report)"),
                s.max_joint_angle_deg,
                f64::INFINITY,
            ));
            // CPU per thread: the calling thread's CPU, or with the intervals on the pool all
            // threads' CPU over the pool size
            let times = [
                ("worst", s.solve_cpu_per_thread_worst_s),
                ("median", s.solve_cpu_per_thread_median_s),
            ];
            for (what, t) in times {
                out.push(Metric::at_most(
                    format!(
                        "{name} plant ω0={w}: {what} sample solve time (s, CPU per thread, report)"
                    ),
                    t,
                    f64::INFINITY,
                ));
            }
            // the work per sample, the same on any machine
            type Pick = fn(&ocp_transcription::Evaluations) -> usize;
            let picks: [(&str, Pick); 2] =
                [("right-hand sides", |e| e.rhs), ("Jacobians", |e| e.jacobians)];
            for (what, pick) in picks {
                let counts: Vec<f64> =
                    r.samples.iter().map(|x| pick(&x.evaluations) as f64).collect();
                let mean = counts.iter().sum::<f64>() / counts.len().max(1) as f64;
                let most = counts.iter().copied().fold(0.0, f64::max);
                for (stat, v) in [("mean", mean), ("largest", most)] {
                    out.push(Metric::at_most(
                        format!("{name} plant ω0={w}: {what} per sample, {stat} (count, report)"),
                        v,
                        f64::INFINITY,
                    ));
                }
            }
        }
    }
    Ok(out)
}

/// The ω0 that `mpc/3d-exact-joints` runs per plant: the largest ω0 of the scene's sweep that
/// meets the criterion on each plant (docs/mpc.md, "3D sweep": FE 1.5, the whole sweep; ROM
/// 1.375, ✗ at 1.5). The two loops ≈ 8 s CPU.
const EXACT_JOINTS_3D_OMEGAS: &[(PlantKind, &[f64])] =
    &[(PlantKind::Fe, &[1.5]), (PlantKind::Rom, &[1.375])];

/// The real-time goal on the real-time NMPC of the shipped scenes, FE plant: 2D
/// `ControllerSettings::real_time(false)` (RTI, no relaxed retry, full steps;
/// `scenes/paper-2d-mpc.toml`), 3D `ControllerSettings::real_time_spatial()` with the `k_u`
/// option (`scenes/paper-3d-mpc-ku1.toml`, which stabilises every ω0 = 0.25…1.0). Asserts
/// the criterion per run and each closed loop's thread CPU time (controller and FE plant)
/// against 10 s. The runs are sequential and timed in thread CPU time, so a loaded machine
/// does not fail the case (wall clock belongs to the benches). The controller's per-sample
/// solve times (`SampleReport::solve_time`, thread CPU) are reported here; `mpc/shipped-scenes`
/// asserts them against τs for every shipped scene.
fn real_time() -> CaseOutcome {
    let mut out = Vec::new();
    for (three_d, omegas) in [(false, &OMEGAS_2D[..]), (true, &[0.25, 0.5, 0.75, 1.0][..])] {
        let (setup, c) = if three_d {
            (setup_3d_ku_option()?, ControllerSettings::real_time_spatial())
        } else {
            let sc = Scenario::paper_2d(ELEMENTS).map_err(err)?;
            (Setup::new(&sc).map_err(err)?, ControllerSettings::real_time(false))
        };
        let tag = if three_d { "3D" } else { "2D" };
        let (mut worst, mut cpu) = (0.0f64, 0.0f64);
        for &w in omegas {
            let (t, r) = ocp_transcription::thread_cpu_timed(|| run(&setup, w, &c, PlantKind::Fe));
            let r = r.map_err(err)?;
            criterion(&r.summary, &mut out);
            cpu = cpu.max(t);
            worst = worst.max(r.summary.solve_time_worst_s);
        }
        out.push(Metric::at_most(
            format!("{tag}: worst per-sample solve time, thread CPU (s, report)"),
            worst,
            f64::INFINITY,
        ));
        out.push(Metric::at_most(
            format!("{tag}: slowest closed loop thread CPU time (s)"),
            cpu,
            10.0,
        ));
    }
    Ok(out)
}
