//! Diagnostic of the 3D model/plant consistency (issue 6, must-show 2): open-loop pulses of
//! each input alone (amplitude `A` for 0.2 s, then 0.2 s free) from rest, and free motion
//! after the disturbance ω0, replayed on the FE plant and on the modal model; prints the
//! rigid and elastic velocity coordinates of both (projected FE state) and the joint angles.
//! `inputs3d [A] [ω0]`; env `MPC_U=u1,…` (a given input after the disturbance), `MPC_MODES=n`
//! (modes per elastic family), `MPC_FREE=n` (n free output intervals after `MPC_U`), `MPC_GJ=k` (torsional stiffness), `MPC_DT=h` (FE time step), `MPC_N=n` (elements per link).
use mpc::{open_loop, PlantKind, Scenario, Setup};

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let amp: f64 = a.get(1).map_or(Ok(1.0), |s| s.parse())?;
    let omega0: f64 = a.get(2).map_or(Ok(1.0), |s| s.parse())?;
    // `MPC_N=n`: n elements per link instead of the paper's 50
    let n_el: usize = std::env::var("MPC_N").map_or(Ok(50), |v| v.parse())?;
    let mut scenario = Scenario::paper_3d(n_el)?;
    // `MPC_MODES=n`: n modes of each elastic family instead of the paper's 4
    if let Ok(v) = std::env::var("MPC_MODES") {
        let n: usize = v.parse()?;
        scenario.selection = modal_rom::ModeSelection::ByKind(modal_rom::KindCounts {
            rigid: 4,
            axial: n,
            torsion: n,
            bending_e2: n,
            bending_e3: n,
            mixed: 0,
        });
    }
    // `MPC_GJ=k`: torsional stiffness k instead of the paper's 0.05 (suspect of the mismatch)
    if let Ok(v) = std::env::var("MPC_GJ") {
        let gj: f64 = v.parse()?;
        let d2 =
            nalgebra::Matrix6::from_diagonal(&nalgebra::Vector6::new(1.0, 0.0, 0.0, 1.0, 1.0, 1.0))
                * 1e-4;
        let section = intrinsic_beam::Section::from_diagonals(
            [1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4],
            [1000.0, 1e5, 1e5, gj, 1.0, 2.0],
        )?
        .with_damping(nalgebra::Matrix6::zeros(), nalgebra::Matrix6::zeros(), d2)?;
        scenario.structure = multibody_constraints::samples::paper_3d(section, n_el, 0.0)?;
    }
    // `MPC_DT=h`: FE plant time step h instead of 1e-3 (time convergence of the plant)
    if let Ok(v) = std::env::var("MPC_DT") {
        scenario.plant.dt = v.parse()?;
    }
    let setup = Setup::new(&scenario)?;
    let (nr, m) = (setup.rom.n_rigid(), setup.rom.n_modes());
    let nu = scenario.inputs.len();
    let compare = |label: &str,
                   w0: f64,
                   inputs: &[Vec<f64>]|
     -> Result<(), Box<dyn std::error::Error>> {
        let fe = open_loop(&setup, w0, inputs, PlantKind::Fe)?;
        let ro = open_loop(&setup, w0, inputs, PlantKind::Rom)?;
        for (f, r) in fe.iter().zip(&ro).step_by(4) {
            let d: Vec<f64> = f.q.iter().zip(&r.q).map(|(x, y)| x - y).collect();
            println!(
                "{label} t={:.2} q1r fe={:.4?} rom={:.4?} |Δq1r|={:.2e} |q1e| fe={:.3e} rom={:.3e} |Δq1e|={:.2e} ang fe={:.2?} rom={:.2?}",
                f.t,
                &f.q[..nr],
                &r.q[..nr],
                norm(&d[..nr]),
                norm(&f.q[nr..m]),
                norm(&r.q[nr..m]),
                norm(&d[nr..m]),
                f.joint_angles.iter().map(|v| v.to_degrees()).collect::<Vec<_>>(),
                r.joint_angles.iter().map(|v| v.to_degrees()).collect::<Vec<_>>(),
            );
        }
        Ok(())
    };
    for k in 0..nu {
        let mut inputs = vec![vec![0.0; nu]; 8];
        for u in inputs.iter_mut().take(4) {
            u[k] = amp;
        }
        compare(&format!("pulse {}", scenario.inputs[k].name()), 0.0, &inputs)?;
    }
    compare("free", omega0, &vec![vec![0.0; nu]; 20])?;
    // `MPC_U=u1,u2,…`: that constant input for 0.2 s after the disturbance ω0
    if let Ok(v) = std::env::var("MPC_U") {
        let u: Vec<f64> = v.split(',').map(|s| s.parse()).collect::<Result<_, _>>()?;
        // `MPC_FREE=n`: then n output intervals without input (the elbow's free response)
        let free: usize = std::env::var("MPC_FREE").map_or(Ok(0), |v| v.parse())?;
        let mut history = vec![u; 8];
        history.extend(vec![vec![0.0; nu]; free]);
        compare("given u", omega0, &history)?;
    }
    Ok(())
}
