//! Verification cases of the exact-joints reduced model (theory.md §10; names
//! `modal-rom/exact-joints-*`): accuracy against the FE plant open loop (spin plus tip kick,
//! 2D and 3D; free whip of link 2), energy and compatibility over long implicit-midpoint
//! runs with the elbow swinging past 90°, and a table of error against state count for the
//! candidate bases.

use crate::{Case, CaseOutcome, Metric, Tier};
use faer::Mat;
use intrinsic_beam::rotation::{quat_conj, quat_mul};
use intrinsic_beam::{Amplitude, LoadFrame, PointLoad, Section};
use modal_rom::exact_joints::{self, ExactJointsRom, LinkBasisSettings};
use modal_rom::samples::{self, paper_2d_selection, paper_3d_selection};
use modal_rom::{BasisSettings, ModalRom, ModeSelection, RomOptions, StructureModel};
use multibody_constraints::Structure;
use multibody_constraints::{Plant, PlantSettings};
use nalgebra::{Vector3, Vector4, Vector6};
use std::f64::consts::PI;

/// The cases of the exact-joints model.
pub fn cases() -> Vec<Case> {
    vec![
        Case { name: "modal-rom/exact-joints-spin-kick-2d", tier: Tier::Full, run: spin_kick_2d },
        Case { name: "modal-rom/exact-joints-spin-kick-3d", tier: Tier::Full, run: spin_kick_3d },
        Case { name: "modal-rom/exact-joints-free-whip", tier: Tier::Full, run: free_whip },
        Case { name: "modal-rom/exact-joints-energy", tier: Tier::Full, run: energy },
        Case { name: "mpc/exact-joints-closed-loop-2d", tier: Tier::Full, run: closed_loop_2d },
    ]
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

const N: usize = 20;
const DT: f64 = 2e-3;
const KICK: f64 = 0.05;
const KICK_TIME: f64 = 0.05;
const EVERY: usize = 5;

/// One open-loop run: initial state, follower tip kick, horizon.
#[derive(Clone, Copy, Debug)]
struct Run {
    spatial: bool,
    /// Spin about the root (2D: ω0 e2; 3D: ω0 (e2 + e3)).
    omega0: f64,
    /// Rate of link 2 about the elbow (e2), link 1 at rest.
    whip: f64,
    kick: bool,
    horizon: f64,
    damped: bool,
}

impl Run {
    fn section(&self) -> Section {
        match (self.spatial, self.damped) {
            (false, true) => Section::paper_2d(),
            (false, false) => Section::paper_2d().undamped(),
            (true, true) => Section::paper_3d(),
            (true, false) => Section::paper_3d().undamped(),
        }
    }

    fn structure(&self, angle: f64) -> Result<Structure, String> {
        if self.spatial {
            multibody_constraints::samples::paper_3d(self.section(), N, angle)
        } else {
            multibody_constraints::samples::paper_2d(self.section(), N, angle)
        }
        .map_err(err)
    }

    fn initial(&self, s: &Structure) -> Vec<f64> {
        let w = self.omega0;
        let spin = if self.spatial { Vector3::new(0.0, w, w) } else { Vector3::new(0.0, w, 0.0) };
        let mut x = s.rigid_rotation_state(spin, Vector3::zeros());
        if self.whip != 0.0 {
            let elbow = s.reference()[1].r[0];
            let y = s.rigid_rotation_state(Vector3::new(0.0, self.whip, 0.0), elbow);
            let o = s.offset(1);
            for i in o..x.len() {
                x[i] += y[i];
            }
        }
        x
    }

    fn force(&self) -> Vector3<f64> {
        if !self.kick {
            Vector3::zeros()
        } else if self.spatial {
            Vector3::new(0.0, KICK, KICK)
        } else {
            Vector3::new(0.0, 0.0, KICK)
        }
    }

    fn input(&self) -> Vec<f64> {
        let f = self.force();
        if self.spatial {
            vec![0.0, 0.0, f.x, f.y, f.z]
        } else {
            vec![0.0, f.x, f.z]
        }
    }

    fn steps(&self) -> (usize, usize) {
        ((self.horizon / DT).round() as usize, (KICK_TIME / DT).round() as usize)
    }
}

/// Rotation vector of a relative quaternion.
fn rotvec(mut rel: Vector4<f64>) -> [f64; 3] {
    if rel[0] < 0.0 {
        rel = -rel;
    }
    let s = (rel[1] * rel[1] + rel[2] * rel[2] + rel[3] * rel[3]).sqrt();
    let scale = if s > 1e-150 { 2.0 * s.atan2(rel[0]) / s } else { 2.0 };
    [rel[1] * scale, rel[2] * scale, rel[3] * scale]
}

type Angles = Vec<[f64; 3]>;

fn fe_angles(run: Run) -> Result<Angles, String> {
    let s = run.structure(0.0)?;
    let x0 = run.initial(&s);
    let mut plant =
        Plant::new(s, PlantSettings { dt: DT, ..PlantSettings::default() }).map_err(err)?;
    plant.set_state(&x0).map_err(err)?;
    let f = run.force();
    if run.kick {
        plant.loads_mut(1).point.push(PointLoad {
            node: N,
            frame: LoadFrame::Follower,
            value: Vector6::new(f.x, f.y, f.z, 0.0, 0.0, 0.0),
            amplitude: Amplitude::Constant,
        });
    }
    let (steps, on) = run.steps();
    let mut out = Vec::new();
    for k in 0..=steps {
        if k % EVERY == 0 {
            let kin = plant.kinematics();
            out.push(rotvec(quat_mul(&quat_conj(&kin[0].xi[N]), &kin[1].xi[0])));
        }
        if k == on {
            plant.loads_mut(1).point.clear();
        }
        if k < steps {
            plant.step().map_err(err)?;
        }
    }
    Ok(out)
}

fn inputs(run: Run, s: &Structure, m: &StructureModel) -> Result<Vec<modal_rom::Input>, String> {
    if run.spatial { samples::inputs_3d(s, m) } else { samples::inputs_2d(s, m) }.map_err(err)
}

/// Candidate bases of theory.md §10.6.
#[derive(Clone, Debug)]
enum Basis {
    /// Rigid link motions + per-link pieces of the 0° constrained modes (rigid + `n` elastic).
    PerLink(usize),
    /// Constrained modes (rigid + `n` elastic) at each angle, split per link, + rigid motions.
    MultiAngle(usize, Vec<f64>),
}

impl Basis {
    fn label(&self) -> String {
        match self {
            Basis::PerLink(n) => format!("per-link 0° rigid+{n}"),
            Basis::MultiAngle(n, a) => format!(
                "multi-angle rigid+{n} at {:?}°",
                a.iter().map(|x| (x * 180.0 / PI).round()).collect::<Vec<_>>()
            ),
        }
    }
}

fn ej_model(run: Run, basis: &Basis) -> Result<(ExactJointsRom, Structure), String> {
    let s = run.structure(0.0)?;
    let model = StructureModel::new(&s).map_err(err)?;
    let (n, angles) = match basis {
        Basis::PerLink(n) => (*n, vec![0.0]),
        Basis::MultiAngle(n, a) => (*n, a.clone()),
    };
    let mut fields: Vec<Mat<f64>> = Vec::new();
    for a in angles {
        let sa = run.structure(a)?;
        let ma = StructureModel::new(&sa).map_err(err)?;
        let b = ma.modes(&BasisSettings::default()).map_err(err)?;
        let sel = b.select(&ModeSelection::Lowest(b.n_rigid() + n)).map_err(err)?;
        fields.push(sel.phi1().to_owned());
    }
    let refs: Vec<_> = fields.iter().map(|f| f.as_ref()).collect();
    let inp = inputs(run, &s, &model)?;
    let damping = run.damped.then_some(&model.damping);
    let rom =
        exact_joints::from_fields(&s, &model, &refs, &LinkBasisSettings::default(), damping, &inp)
            .map_err(err)?;
    Ok((rom, s))
}

fn ej_angles(run: Run, rom: &ExactJointsRom, s: &Structure) -> Result<(Angles, f64), String> {
    let x0 = run.initial(s);
    let mut x = rom.project_fe(&x0, s.reference()).map_err(err)?;
    let mut u = run.input();
    let (steps, on) = run.steps();
    let mut out = Vec::new();
    let start = crate::thread_cpu().unwrap_or(f64::NAN);
    for k in 0..=steps {
        if k % EVERY == 0 {
            out.push(rotvec(rom.joint_quaternion(&x, 0)));
        }
        if k == on {
            u.iter_mut().for_each(|v| *v = 0.0);
        }
        if k < steps {
            rom.midpoint_step(&mut x, &u, DT, 1e-12, 30).map_err(err)?;
        }
    }
    Ok((out, crate::thread_cpu().unwrap_or(f64::NAN) - start))
}

/// The paper's model (eq. 29 without quaternion states), joint angle from the two joint
/// ends' rates as in `modal-rom/rom-vs-fe`.
fn paper_angles(run: Run) -> Result<Angles, String> {
    use intrinsic_beam::rotation::quaternion_step;
    let s = run.structure(0.0)?;
    let model = StructureModel::new(&s).map_err(err)?;
    let basis = model.modes(&BasisSettings::default()).map_err(err)?;
    let sel = basis
        .select(&if run.spatial { paper_3d_selection() } else { paper_2d_selection() })
        .map_err(err)?;
    let inp = inputs(run, &s, &model)?;
    let opts = RomOptions { quaternions: false, ..RomOptions::default() };
    let damping = run.damped.then_some(&model.damping);
    let rom = ModalRom::new(&sel, damping, &inp, &opts).map_err(err)?;
    let mut q = rom.project_full(&run.initial(&s), None).map_err(err)?;
    let layout = rom.layout();
    let m = rom.n_modes();
    let rows = |b: usize, nd: usize| -> Vec<Vector3<f64>> {
        (0..m)
            .map(|j| {
                if layout.k() == 6 {
                    Vector3::from([3, 4, 5].map(|c| sel.phi1()[(layout.x1_index(b, nd, c), j)]))
                } else {
                    Vector3::new(0.0, sel.phi1()[(layout.x1_index(b, nd, 2), j)], 0.0)
                }
            })
            .collect()
    };
    let (ra, rb) = (rows(0, N), rows(1, 0));
    let rate = |r: &[Vector3<f64>], q: &[f64]| {
        r.iter().zip(q).fold(Vector3::zeros(), |a, (v, c)| a + v * *c)
    };
    let (mut xa, mut xb) = (s.reference()[0].xi[N], s.reference()[1].xi[0]);
    let mut u = run.input();
    let (steps, on) = run.steps();
    let mut out = Vec::new();
    for k in 0..=steps {
        if k % EVERY == 0 {
            out.push(rotvec(quat_mul(&quat_conj(&xa), &xb)));
        }
        if k == on {
            u.iter_mut().for_each(|v| *v = 0.0);
        }
        if k < steps {
            let before = q[..m].to_vec();
            rom.midpoint_step(&mut q, &u, DT, 1e-12, 30).map_err(err)?;
            let mid: Vec<f64> = before.iter().zip(&q[..m]).map(|(a, b)| 0.5 * (a + b)).collect();
            xa = quaternion_step(&xa, &rate(&ra, &mid), DT);
            xb = quaternion_step(&xb, &rate(&rb, &mid), DT);
        }
    }
    Ok(out)
}

/// `max_t |Δ rotation vector| / max_t |FE rotation vector|`, and the FE excursion.
fn angle_error(model: &Angles, fe: &Angles) -> (f64, f64) {
    let norm = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let (mut e, mut s) = (0.0f64, 0.0f64);
    for (a, b) in model.iter().zip(fe) {
        e = e.max(norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]));
        s = s.max(norm(*b));
    }
    (e / s, s)
}

fn compare(
    run: Run,
    bases: &[Basis],
    label: &str,
    bound: f64,
    out: &mut Vec<Metric>,
) -> CaseOutcome {
    let fe = fe_angles(run)?;
    let paper = paper_angles(run)?;
    let (ep, excursion) = angle_error(&paper, &fe);
    let fe_max = fe.iter().map(|a| a[1].abs().max(a[2].abs())).fold(0.0f64, f64::max);
    eprintln!(
        "\n{label}: FE joint rotation max {:.2}° ; paper model error {ep:.3e} (max {:.1}°)",
        excursion * 180.0 / PI,
        paper
            .iter()
            .map(|a| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt())
            .fold(0.0f64, f64::max)
            * 180.0
            / PI
    );
    let _ = fe_max;
    out.push(Metric::at_most(
        format!("{label}: paper model joint-angle error (table)"),
        ep,
        f64::MAX,
    ));
    eprintln!(
        "| basis | state count (p + p2 + quaternions) | joint-angle error | thread CPU (s) |"
    );
    let mut best = f64::MAX;
    for b in bases {
        let (rom, s) = ej_model(run, b)?;
        let (track, cpu) = ej_angles(run, &rom, &s)?;
        let (e, _) = angle_error(&track, &fe);
        eprintln!(
            "| {} | {} ({} + {} + {}) | {e:.3e} | {cpu:.1} |",
            b.label(),
            rom.n_state(),
            rom.n_p(),
            rom.n_p2(),
            rom.n_state() - rom.n_p() - rom.n_p2()
        );
        out.push(Metric::at_most(
            format!("{label}, {} ({} states): joint-angle error (table)", b.label(), rom.n_state()),
            e,
            f64::MAX,
        ));
        best = best.min(e);
    }
    out.push(Metric::at_most(
        format!("{label}: exact-joints joint-angle error (chosen basis)"),
        best,
        bound,
    ));
    Ok(std::mem::take(out))
}

fn chosen_2d() -> Vec<Basis> {
    vec![
        Basis::PerLink(4),
        Basis::PerLink(8),
        Basis::MultiAngle(4, vec![0.0, PI / 4.0, PI / 2.0]),
        Basis::MultiAngle(8, vec![0.0, PI / 4.0, PI / 2.0]),
    ]
}

/// 2D spin plus kick, ω0 = 1 (and 0.1), 2 s, joint-angle error ≤ 3 %.
fn spin_kick_2d() -> CaseOutcome {
    let mut all = Vec::new();
    for omega0 in [0.1, 1.0] {
        let run = Run { spatial: false, omega0, whip: 0.0, kick: true, horizon: 2.0, damped: true };
        let mut out = Vec::new();
        all.extend(compare(
            run,
            &chosen_2d(),
            &format!("2D spin-kick ω0 = {omega0}"),
            0.03,
            &mut out,
        )?);
    }
    Ok(all)
}

/// 3D: the paper's diagonal spin plus kick, ω0 = 1, 2 s (ω0 = 0: the
/// truncation level of the same bases, as a table).
fn spin_kick_3d() -> CaseOutcome {
    let bases =
        vec![Basis::PerLink(8), Basis::PerLink(16), Basis::MultiAngle(8, vec![0.0, PI / 4.0])];
    let mut all = Vec::new();
    for omega0 in [0.0, 1.0] {
        let run = Run { spatial: true, omega0, whip: 0.0, kick: true, horizon: 2.0, damped: true };
        let bound = if omega0 == 0.0 { f64::MAX } else { 0.03 };
        let mut out = Vec::new();
        all.extend(compare(run, &bases, &format!("3D spin-kick ω0 = {omega0}"), bound, &mut out)?);
    }
    Ok(all)
}

/// Free whip, link 2 spun about the elbow at 2 rad/s from rest, 5 s.
fn free_whip() -> CaseOutcome {
    let run =
        Run { spatial: false, omega0: 0.0, whip: 2.0, kick: false, horizon: 5.0, damped: true };
    let mut out = Vec::new();
    compare(run, &chosen_2d(), "2D free whip 2 rad/s", 0.03, &mut out)
}

/// Energy: undamped, unforced, 1e4 implicit-midpoint steps with the elbow swinging past
/// 90°: relative energy drift and compatibility residual.
fn energy() -> CaseOutcome {
    let run =
        Run { spatial: false, omega0: 0.5, whip: 4.0, kick: false, horizon: 0.0, damped: false };
    let (rom, s) = ej_model(run, &Basis::PerLink(4))?;
    let mut x = rom.project_fe(&run.initial(&s), s.reference()).map_err(err)?;
    let u = vec![0.0; rom.n_inputs()];
    let e0 = rom.energy(&x);
    let (mut drift, mut res, mut turned, mut norm) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for k in 0..10_000 {
        rom.midpoint_step(&mut x, &u, 1e-3, 1e-13, 50).map_err(err)?;
        drift = drift.max((rom.energy(&x) - e0).abs() / e0);
        if k % 10 == 0 {
            let v = rom.link_velocities(&x).map_err(err)?;
            let vmax = v.iter().fold(0.0f64, |m, a| m.max(a.abs()));
            res = res.max(rom.compatibility_residual(&x).map_err(err)? / vmax);
        }
        let q = rom.joint_quaternion(&x, 0);
        turned = turned.max(rotvec(q)[1].abs());
        norm = norm.max((q.norm() - 1.0).abs());
    }
    eprintln!(
        "energy run: {} states, max elbow angle {:.0}°, energy drift {drift:.2e}, compatibility {res:.2e}, |ξ| − 1 {norm:.1e}",
        rom.n_state(),
        turned * 180.0 / PI
    );
    Ok(vec![
        Metric::at_least("max elbow angle (deg)", turned * 180.0 / PI, 90.0),
        Metric::at_most("relative energy drift over 1e4 midpoint steps", drift, 1e-10),
        Metric::at_most("compatibility residual |A(ξ)q1| / |q1|", res, 1e-10),
        Metric::at_most("| |ξ_elbow| − 1 |", norm, 1e-12),
    ])
}

/// 2D closed loops on the FE plant with the exact-joints NMPC, the
/// paper's weights, horizon and sampling, no LMPC fallback (SQP as the controller's NMPC:
/// Gauss–Newton, merit line search, Lawson RK4 × 16, ≤ 10 iterations, warm start by the
/// shifted plan). Reported: `V(T)/V(0)` of the exact-joints cost on the projected plant
/// state and the final root rate; stabilised when `V(T)/V(0) ≤ 0.05`.
pub fn closed_loop_2d() -> CaseOutcome {
    use mpc::{ControllerSettings, ExactDynamics, MpcSettings};
    use ocp_transcription::{Ocp, SqpMode, SqpSettings, SqpSolver};
    let mut out = Vec::new();
    let settings = MpcSettings::default();
    let ctrl = ControllerSettings::full_sqp();
    let duration = 7.5;
    for omega0 in [0.5, 1.0, 2.0] {
        let run =
            Run { spatial: false, omega0, whip: 0.0, kick: false, horizon: 0.0, damped: true };
        let (rom, s) = ej_model(run, &Basis::PerLink(4))?;
        let dynamics = ExactDynamics::new(rom.clone()).map_err(err)?;
        let w = dynamics.weights(&settings, 2.0, &[1.0], None, &[None]).map_err(err)?;
        let (nx, nu) = (rom.n_state(), rom.n_inputs());
        let mut ocp =
            Ocp::new(nx, nu, settings.timing.horizon, settings.timing.intervals).map_err(err)?;
        ocp.q = w.q.clone();
        ocp.r = w.r.clone();
        ocp.x_ref = w.x_ref.clone();
        ocp.u_ref = nalgebra::DVector::zeros(nu);
        ocp.u_min = nalgebra::DVector::from_element(nu, -settings.cost.u_max);
        ocp.u_max = nalgebra::DVector::from_element(nu, settings.cost.u_max);
        let sqp = SqpSettings {
            mode: SqpMode::Sqp,
            integrator: ctrl.integrator.clone(),
            globalisation: ctrl.globalisation,
            levenberg_marquardt: ctrl.levenberg_marquardt,
            max_iterations: ctrl.max_iterations,
            kkt_tolerance: ctrl.kkt_tolerance,
            qp_form: ctrl.qp_form,
            ..SqpSettings::default()
        };
        let mut solver = SqpSolver::new(dynamics, ocp, sqp).map_err(err)?;
        let mut plant =
            Plant::new(s.clone(), PlantSettings { dt: 1e-3, ..PlantSettings::default() })
                .map_err(err)?;
        plant.set_state(&run.initial(&s)).map_err(err)?;
        let steps = (settings.timing.sampling / 1e-3).round() as usize;
        let samples = (duration / settings.timing.sampling).round() as usize;
        let mut v0 = 0.0;
        let mut failures = 0;
        let mut max_angle = 0.0f64;
        for k in 0..samples {
            let x0 = rom.project_fe(plant.state(), plant.kinematics()).map_err(err)?;
            if k == 0 {
                v0 = w.state_cost(&x0);
                solver.initialize_constant(&x0, &vec![0.0; nu]).map_err(err)?;
            } else {
                solver.shift_time(settings.timing.sampling).map_err(err)?;
            }
            if solver.solve(&x0).is_err() {
                failures += 1;
            }
            let u: Vec<f64> = solver.first_control().iter().copied().collect();
            plant.set_joint_torque("root", None, u[0]).map_err(err)?;
            plant.loads_mut(1).point.clear();
            plant.loads_mut(1).point.push(PointLoad {
                node: N,
                frame: LoadFrame::Follower,
                value: Vector6::new(u[1], 0.0, u[2], 0.0, 0.0, 0.0),
                amplitude: Amplitude::Constant,
            });
            for _ in 0..steps {
                plant.step().map_err(err)?;
            }
            let kin = plant.kinematics();
            max_angle =
                max_angle.max(rotvec(quat_mul(&quat_conj(&kin[0].xi[N]), &kin[1].xi[0]))[1].abs());
        }
        let x_end = rom.project_fe(plant.state(), plant.kinematics()).map_err(err)?;
        let ratio = w.state_cost(&x_end) / v0;
        eprintln!(
            "closed loop 2D ω0 = {omega0}: V(T)/V(0) = {ratio:.3e}, SQP errors {failures}, max elbow {:.1}°",
            max_angle * 180.0 / PI
        );
        // the cost part of the closed-loop criterion (`mpc::RunSummary::stabilised`: V(T)/V(0) < 0.1)
        out.push(Metric::at_most(
            format!("2D ω0 = {omega0}: V(7.5)/V(0), exact-joints NMPC, FE plant"),
            ratio,
            0.1,
        ));
    }
    Ok(out)
}
