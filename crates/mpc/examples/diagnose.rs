//! Diagnostic: one closed loop with the cost `V` split into its parts (q1, q2, Kξ-field,
//! joint jump, and the shifting-equilibrium coefficient) every `every` records.
//! `diagnose [2d|3d] [nmpc|lmpc] [fe|rom] [ω0] [every]`.
use mpc::{
    run, Controller, ControllerKind, ControllerSettings, PlantKind, RomDynamics, Scenario, Setup,
};
use nalgebra::DVector;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let dim = a.get(1).map_or("2d", |s| s.as_str());
    let kind = match a.get(2).map_or("lmpc", |s| s.as_str()) {
        "nmpc" => ControllerKind::Nmpc,
        _ => ControllerKind::Lmpc,
    };
    let plant = match a.get(3).map_or("rom", |s| s.as_str()) {
        "fe" => PlantKind::Fe,
        _ => PlantKind::Rom,
    };
    let omega0: f64 = a.get(4).map_or(Ok(0.5), |s| s.parse())?;
    let every: usize = a.get(5).map_or(Ok(5), |s| s.parse())?;
    let mut scenario = if dim == "3d" { Scenario::paper_3d(50)? } else { Scenario::paper_2d(50)? };
    let env = |k: &str| std::env::var(k).ok().map(|v| v.parse::<f64>()).transpose();
    if let Some(v) = env("MPC_TS")? {
        scenario.mpc.sampling = v;
    }
    if let Some(v) = env("MPC_NC")? {
        scenario.mpc.intervals = v as usize;
    }
    if let Some(v) = env("MPC_KDXI")? {
        scenario.mpc.k_dxi = v;
    }
    if let Some(v) = env("MPC_KX")? {
        scenario.mpc.kx1 = v;
        scenario.mpc.kx2 = v;
    }
    if let Some(v) = env("MPC_KU")? {
        scenario.mpc.ku = v;
    }
    match std::env::var("MPC_GRID").as_deref() {
        Ok("absolute") => scenario.mpc.control_grid = mpc::ControlGrid::Absolute,
        Ok("sample") => scenario.mpc.control_grid = mpc::ControlGrid::Sample,
        _ => {}
    }
    let quiet = std::env::var("MPC_QUIET").is_ok();
    let setup = Setup::new(&scenario)?;
    let rom = &setup.rom;
    let w = &setup.weights;
    let st = &scenario.mpc;
    let (m, nq2, nxi, ox) = (rom.n_modes(), rom.n_q2(), rom.n_xi(), rom.xi_offset());
    println!("omega {:?}", rom.omega());
    println!("kinds {:?}", rom.kinds());
    println!("q2 modes {:?} kept xi {:?}", rom.q2_modes(), rom.quaternion().map(|q| &q.kept));
    println!("k_xi {:?}", w.k_xi);
    println!("A_xi diag {:?}", (0..nxi).map(|i| w.a_xi[(i, i)]).collect::<Vec<_>>());
    println!("A_dxi diag {:?}", (0..nxi).map(|i| w.a_dxi[(i, i)]).collect::<Vec<_>>());
    let mut c = ControllerSettings::of(kind);
    if let Some(v) = env("MPC_SUBSTEPS")? {
        c.integrator.substeps = v as usize;
    }
    let r = run(&setup, omega0, &c, plant)?;
    for rec in r.records.iter().step_by(every).filter(|_| !quiet) {
        let q = &rec.q;
        let v1 = 0.5 * st.kx1 * q[..m].iter().map(|v| v * v).sum::<f64>();
        let v2 = 0.5 * st.kx2 * q[m..m + nq2].iter().map(|v| v * v).sum::<f64>();
        let mut e = DVector::from_column_slice(&q[ox..ox + nxi]);
        e[0] -= 1.0;
        let ke = DVector::from_fn(nxi, |i, _| w.k_xi[i] * e[i]);
        let vk = 0.5 * (&w.a_xi * &ke).dot(&ke);
        let vj = 0.5 * st.k_dxi * (&w.a_dxi * &e).dot(&e);
        // the φξ0 part alone
        let v0 = 0.5 * w.a_xi[(0, 0)] * e[0] * e[0] * w.k_xi[0] * w.k_xi[0];
        println!(
            "t={:.2} V={:.3e} q1={:.2e} q2={:.2e} Kxi={:.2e} (xi0 {:.2e}, dxi0={:.2e}) joint={:.2e} ang={:.4?} u={:.3?}",
            rec.t, rec.v_state, v1, v2, vk, v0, e[0], vj, rec.joint_angles, rec.u
        );
        println!(
            "    q1={:.4?}\n    q2={:.4?}\n    xi={:.4?}",
            &q[..m],
            &q[m..m + nq2],
            e.as_slice()
        );
    }
    if let Some(tp) = env("MPC_PLAN_AT")? {
        // the plan of a fresh controller at the record nearest tp: its cost at the nodes
        // against its cost sampled finely between them (nonlinear ROM, RK4, dt = 1e-3)
        let rec =
            r.records.iter().min_by(|a, b| (a.t - tp).abs().total_cmp(&(b.t - tp).abs())).unwrap();
        let mut ctrl = Controller::new(RomDynamics::new(rom)?, w, st, &c)?;
        let rep = ctrl.step(rec.t, &rec.q)?;
        let (xs, us) = ctrl.plan();
        let dt_i = st.horizon / st.intervals as f64;
        let fine = 250usize;
        let h = dt_i / fine as f64;
        let mut q = rec.q.clone();
        let (mut node_int, mut fine_int) = (0.0, 0.0);
        let mut vprev = w.state_cost(&q);
        let mut vnode_prev = vprev;
        for (k, u) in us.iter().enumerate() {
            let mut vmax: f64 = 0.0;
            for _ in 0..fine {
                rom.rk4_step(&mut q, u.as_slice(), h)?;
                let v = w.state_cost(&q);
                fine_int += 0.5 * h * (v + vprev);
                vprev = v;
                vmax = vmax.max(v);
            }
            node_int += 0.5 * dt_i * (vnode_prev + vprev);
            if k < 8 || k % 4 == 3 {
                let xp = xs[k + 1].as_slice();
                let dmax = xp.iter().zip(&q).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                println!(
                    "  plan k={k} V(sim node)={:.3e} V(plan node)={:.3e} |plan-sim|max={:.2e} max V in interval={:.3e} u={:.3?}",
                    vprev, w.state_cost(xp), dmax, vmax, u.as_slice()
                );
                if k == 0 {
                    println!("    plan x1={:.4?}\n    sim  x1={:.4?}", xp, q);
                }
            }
            vnode_prev = vprev;
        }
        println!(
            "PLAN t={:.2} cost={:.3e} ∫V trapezoid on nodes={:.3e} ∫V fine={:.3e} ratio={:.2}",
            rec.t,
            rep.cost,
            node_int,
            fine_int,
            fine_int / node_int
        );
    }
    let rises = r.samples.windows(2).filter(|p| p[1].cost > p[0].cost).count();
    let late: Vec<f64> = r.samples.iter().filter(|x| x.t >= 2.0).map(|x| x.cost).collect();
    println!(
        "COST J*(t_i+τs) > J*(t_i) in {rises} of {} sample pairs; J* over t ≥ 2 s: min {:.2e} max {:.2e}, last {:.2e}",
        r.samples.len() - 1,
        late.iter().copied().fold(f64::INFINITY, f64::min),
        late.iter().copied().fold(0.0, f64::max),
        r.samples.last().map_or(0.0, |x| x.cost)
    );
    if std::env::var("MPC_REPLAY").is_ok() {
        // replay this run's inputs open loop on the FE plant and on the modal model
        let inputs: Vec<Vec<f64>> =
            r.records[..r.records.len() - 1].iter().map(|x| x.u.clone()).collect();
        let fe = mpc::open_loop(&setup, omega0, &inputs, PlantKind::Fe)?;
        let ro = mpc::open_loop(&setup, omega0, &inputs, PlantKind::Rom)?;
        for (a, b) in fe.iter().zip(&ro).step_by(every) {
            let d = a.q.iter().zip(&b.q).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
            let (i, _) =
                a.q.iter()
                    .zip(&b.q)
                    .enumerate()
                    .map(|(i, (x, y))| (i, (x - y).abs()))
                    .fold((0, 0.0), |m, v| if v.1 > m.1 { v } else { m });
            println!(
                "REPLAY t={:.2} fe angles={:.4?} rom angles={:.4?} V fe={:.3e} rom={:.3e} |Δq|max={:.3e} at {i} rigid fe={:.4?} rom={:.4?}",
                a.t, a.joint_angles, b.joint_angles, a.v_state, b.v_state, d, &a.q[..2], &b.q[..2]
            );
        }
    }
    let s = &r.summary;
    println!(
        "SUMMARY {} {} w0={} V={:.3e} rigid={:.2e} orient={:.2}/{:.1} joint={:.1} stab={} Vmax7-7.5={:.3e}",
        s.controller, s.plant, s.omega0, s.v_ratio_final, s.rigid_rate_ratio,
        s.orientation_error_deg, s.max_orientation_deg, s.max_joint_angle_deg, s.stabilised,
        r.records.iter().filter(|x| x.t >= 7.0 - 1e-9).map(|x| x.v_state).fold(0.0, f64::max)
            / r.records[0].v_state
    );
    Ok(())
}
