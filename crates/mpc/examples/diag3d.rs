//! Diagnostic of the 3D closed loop (issue 6, must-show 2): one run, then per 0.25 s the cost
//! split (rigid / elastic velocities, strains, Kξ field, joint jump), the root node's angle
//! against the root link's chord angle and the angle carried by the rigid quaternion modes
//! alone, the per-sample strategy, the one-sample prediction error of the controller's model
//! against the plant (projected), and the end state's cost per mode.
//! `diag3d [nmpc|lmpc] [fe|rom] [ω0]` (env `MPC_GRID=absolute` for the option, `MPC_PURE` for
//! the NMPC without retry and fallback).
use mpc::{
    run, Controller, ControllerKind, ControllerSettings, PlantKind, RomDynamics, Scenario, Setup,
};
use nalgebra::{DVector, Vector3, Vector4};

fn angle(a: &Vector4<f64>, b: &Vector4<f64>) -> f64 {
    let d = (a.dot(b) / (a.norm() * b.norm())).abs().min(1.0);
    2.0 * d.acos()
}

fn fmt(v: impl Iterator<Item = f64>) -> String {
    v.map(|x| format!("{x:.1e}")).collect::<Vec<_>>().join(" ")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let kind = match a.get(1).map_or("nmpc", |s| s.as_str()) {
        "lmpc" => ControllerKind::Lmpc,
        _ => ControllerKind::Nmpc,
    };
    let plant = match a.get(2).map_or("fe", |s| s.as_str()) {
        "rom" => PlantKind::Rom,
        _ => PlantKind::Fe,
    };
    let omega0: f64 = a.get(3).map_or(Ok(1.0), |s| s.parse())?;
    let mut scenario = Scenario::paper_3d(50)?;
    if std::env::var("MPC_GRID").is_ok_and(|v| v == "absolute") {
        scenario.mpc.control_grid = mpc::ControlGrid::Absolute;
    }
    let setup = Setup::new(&scenario)?;
    let rom = &setup.rom;
    let w = &setup.weights;
    let st = &scenario.mpc;
    let qm = rom.quaternion().ok_or("no quaternion model")?;
    let (m, nq2, nxi, ox, nr) =
        (rom.n_modes(), rom.n_q2(), rom.n_xi(), rom.xi_offset(), rom.n_rigid());
    let root = setup.joint_nodes[setup.root_joint][0];
    println!("joints {:?} root joint {} node {root}", setup.joint_names, setup.root_joint);
    let xi_at = |q: &[f64], n: usize, cols: &dyn Fn(usize) -> bool| -> Vector4<f64> {
        Vector4::from_fn(|k, _| {
            (0..nxi).filter(|&c| cols(c)).map(|c| qm.phi_xi[(4 * n + k, c)] * q[ox + c]).sum()
        })
    };
    let mut c = ControllerSettings::of(kind);
    if std::env::var("MPC_PURE").is_ok() {
        // no retry from the linear plan and no fallback to it: the NMPC's own iterate
        c.retry_relaxation = None;
        c.fallback_to_lmpc = false;
    }
    let r = run(&setup, omega0, &c, plant)?;
    let v0 = r.records[0].v_state;
    let ctrl = Controller::new(RomDynamics::new(rom)?, w, st, &c)?;
    let e_of = |q: &[f64]| {
        let mut e = DVector::from_column_slice(&q[ox..ox + nxi]);
        e[0] -= 1.0;
        e
    };
    let parts = |q: &[f64]| {
        let vr = 0.5 * st.kx1 * q[..nr].iter().map(|v| v * v).sum::<f64>();
        let ve = 0.5 * st.kx1 * q[nr..m].iter().map(|v| v * v).sum::<f64>();
        let v2 = 0.5 * st.kx2 * q[m..m + nq2].iter().map(|v| v * v).sum::<f64>();
        let e = e_of(q);
        let ke = DVector::from_fn(nxi, |i, _| w.k_xi[i] * e[i]);
        let vk = 0.5 * (&w.a_xi * &ke).dot(&ke);
        let vj = 0.5 * st.k_dxi * (&w.a_dxi * &e).dot(&e);
        [vr, ve, v2, vk, vj]
    };
    let snap_every = (scenario.snapshot_interval / scenario.output_interval).round() as usize;
    let per_sample = (st.sampling / scenario.output_interval).round() as usize;
    let xi_ref = setup.reference_xi[root];
    for (i, rec) in r.records.iter().enumerate().step_by(snap_every) {
        let q = &rec.q;
        let p = parts(q);
        let snap = r.snapshots.iter().find(|s| (s.t - rec.t).abs() < 1e-9);
        let chord = snap.map(|s| {
            let l1 = &s.positions[0];
            let d = Vector3::from(l1[l1.len() - 1]) - Vector3::from(l1[0]);
            (d.x / d.norm()).clamp(-1.0, 1.0).acos().to_degrees()
        });
        let rigid_only = angle(&xi_ref, &xi_at(q, root, &|c| c <= nr)).to_degrees();
        let full = angle(&xi_ref, &xi_at(q, root, &|_| true)).to_degrees();
        // one-sample prediction error: the controller's model from this record's state
        // under the recorded inputs, against the (projected) plant state one τs later
        let pred = if i + per_sample < r.records.len() {
            let mut x = q.clone();
            for k in 0..per_sample {
                x = ctrl.predict(&x, &r.records[i + k].u, scenario.output_interval)?;
            }
            let y = &r.records[i + per_sample].q;
            let d: Vec<f64> = x.iter().zip(y).map(|(a, b)| a - b).collect();
            let n = |s: &[f64]| s.iter().map(|v| v * v).sum::<f64>().sqrt();
            let dv = w.state_cost(&x) - w.state_cost(y);
            format!(
                "pred|Δq1r|={:.2e} |Δq1e|={:.2e} |Δq2|={:.2e} |Δqξ|={:.2e} ΔV/V0={:+.2e}",
                n(&d[..nr]),
                n(&d[nr..m]),
                n(&d[m..m + nq2]),
                n(&d[ox..]),
                dv / v0
            )
        } else {
            String::new()
        };
        let strat = r
            .samples
            .iter()
            .filter(|s| s.t >= rec.t - 1e-9 && s.t < rec.t + scenario.snapshot_interval - 1e-9)
            .map(|s| format!("{:?}/{}/{}", s.strategy, s.first_status, s.iterations))
            .collect::<Vec<_>>()
            .join(",");
        println!(
            "t={:.2} V/V0={:.3} [q1r {:.2e} q1e {:.2e} q2 {:.2e} Kξ {:.2e} jump {:.2e}] ang={:.1?}° root node(ROM field) {:.1}° rigid-only {:.1}° chord {:.1?}° {pred} {strat}",
            rec.t,
            rec.v_state / v0,
            p[0], p[1], p[2], p[3], p[4],
            rec.joint_angles.iter().map(|v| v.to_degrees()).collect::<Vec<_>>(),
            full, rigid_only, chord
        );
    }
    let last = &r.records[r.records.len() - 1].q;
    println!("END cost per q1 mode: {}", fmt(last[..m].iter().map(|v| 0.5 * st.kx1 * v * v / v0)));
    println!(
        "END cost per q2 mode: {}",
        fmt(last[m..m + nq2].iter().map(|v| 0.5 * st.kx2 * v * v / v0))
    );
    let e = e_of(last);
    let qx = w.q.view((ox, ox), (nxi, nxi));
    println!(
        "END cost per ξ mode (diag part): {}",
        fmt((0..nxi).map(|i| 0.5 * qx[(i, i)] * e[i] * e[i] / v0))
    );
    println!("END qξ−r: {:.4?}", e.as_slice());
    let s = &r.summary;
    println!(
        "SUMMARY {} {} w0={} V={:.3e} rigid={:.2e} orient={:.2}/{:.1} joint={:.1} stab={} failed1={} relaxed={} fallback={} median={:.3}s wall={:.1}s",
        s.controller, s.plant, s.omega0, s.v_ratio_final, s.rigid_rate_ratio,
        s.orientation_error_deg, s.max_orientation_deg, s.max_joint_angle_deg, s.stabilised,
        s.failed_first_attempts, s.relaxed_samples, s.fallback_samples, s.solve_time_median_s, r.wall_time_s
    );
    Ok(())
}
