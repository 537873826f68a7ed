//! Tests of the first sample's start: settings validation, the decay guess, the extra
//! iterations, the continuation in the initial state and its Levenberg–Marquardt term.

use crate::tests::setup_2d;
use crate::*;
use ocp_transcription::Dynamics;

/// The first sample's settings: an iteration limit of 0, or one with the real-time iteration,
/// is an error naming the field.
#[test]
fn first_sample_settings_validation_names_the_field() {
    let ok =
        ControllerSettings { first_sample_iterations: Some(30), ..ControllerSettings::full_sqp() };
    assert!(ok.validate().is_ok());
    let zero = ControllerSettings { first_sample_iterations: Some(0), ..ok.clone() };
    assert!(zero.validate().unwrap_err().to_string().contains("first_sample_iterations"));
    let rti = ControllerSettings { real_time_iteration: true, ..ok };
    assert!(rti.validate().unwrap_err().to_string().contains("first_sample_iterations"));
}

/// The decay guess puts the first node at the measured state, the last at the reference and
/// the others on the line between (weights `1 − k/Nc`), with the reference controls.
#[test]
fn decay_guess_runs_from_the_state_to_the_reference() {
    let setup = setup_2d();
    let mpc = &setup.scenario.mpc;
    let model = RomDynamics::new(&setup.rom).unwrap();
    let (nx, nu) = (model.nx(), model.nu());
    let ocp = setup.weights.ocp(mpc, nx, nu).unwrap();
    let x_ref = ocp.x_ref.clone();
    let mut solver =
        ocp_transcription::SqpSolver::new(model, ocp, ocp_transcription::SqpSettings::default())
            .unwrap();
    let x0: Vec<f64> = (0..nx).map(|i| x_ref[i] + 0.1 * (i as f64 + 1.0)).collect();
    super::decay_guess(&mut solver, &x0);
    let n = mpc.timing.intervals;
    for (k, s) in solver.states().iter().enumerate() {
        let w = 1.0 - k as f64 / n as f64;
        for i in 0..nx {
            let want = x_ref[i] + w * (x0[i] - x_ref[i]);
            assert!((s[i] - want).abs() <= 1e-15 * (1.0 + want.abs()), "node {k} entry {i}");
        }
    }
    assert_eq!(solver.states()[0].as_slice(), &x0[..]);
    assert!(solver.controls().iter().all(|u| u.iter().all(|v| *v == 0.0)));
}

/// More iterations on the first sample bring its plan closer to the KKT point than the
/// per-sample limit does, and count in the sample's report; from the decay guess the first
/// sample iterates too and applies a finite control within the bounds (on this 2D problem it
/// ends farther from the KKT point than the linear MPC start: the guess is a setting, not a
/// default).
#[test]
fn first_sample_iterations_refine_the_first_plan() {
    let setup = setup_2d();
    let s = &setup.scenario;
    let mut x0: Vec<f64> = setup.weights.x_ref.iter().copied().collect();
    x0[0] = 1.5; // a fast rigid rotation: two SQP iterations are far from converged
    let step = |c: &ControllerSettings| {
        let model = RomDynamics::new(&setup.rom).unwrap();
        Controller::new(model, &setup.weights, &s.mpc, c).unwrap().step(0.0, &x0).unwrap()
    };
    let base = ControllerSettings {
        max_iterations: 2,
        retry_relaxation: None,
        fallback_to_lmpc: false,
        ..ControllerSettings::full_sqp()
    };
    let plain = step(&base);
    let more = step(&ControllerSettings { first_sample_iterations: Some(30), ..base.clone() });
    let decay = step(&ControllerSettings {
        first_sample_iterations: Some(30),
        first_sample_guess: InitialGuess::Decay,
        ..base.clone()
    });
    assert_eq!(plain.iterations, 2, "{plain:?}");
    assert!(more.iterations > 2 && more.iterations <= 32, "{more:?}");
    assert!(more.kkt < plain.kkt, "{} !< {}", more.kkt, plain.kkt);
    assert!(decay.iterations > 2 && decay.kkt.is_finite(), "{decay:?}");
    assert!(decay.u.iter().all(|u| u.is_finite() && u.abs() <= s.mpc.cost.u_max + 1e-9));
}

/// The continuation's settings: 0 steps, more than one step without the first-sample
/// iterations, and a negative, non-finite or orphaned first-sample LM term are errors naming
/// the field.
#[test]
fn continuation_settings_validation_names_the_field() {
    let ok = ControllerSettings {
        first_sample_iterations: Some(30),
        first_sample_continuation: 4,
        first_sample_levenberg_marquardt: Some(1e-3),
        ..ControllerSettings::full_sqp()
    };
    assert!(ok.validate().is_ok());
    let field = |c: ControllerSettings| c.validate().unwrap_err().to_string();
    let zero = ControllerSettings { first_sample_continuation: 0, ..ok.clone() };
    assert!(field(zero).contains("first_sample_continuation"));
    let orphan = ControllerSettings { first_sample_iterations: None, ..ok.clone() };
    let msg =
        field(ControllerSettings { first_sample_levenberg_marquardt: None, ..orphan.clone() });
    assert!(msg.contains("first_sample_continuation"), "{msg}");
    let msg = field(ControllerSettings { first_sample_continuation: 1, ..orphan });
    assert!(msg.contains("first_sample_levenberg_marquardt"), "{msg}");
    for bad in [-1e-3, f64::NAN, f64::INFINITY] {
        let c = ControllerSettings { first_sample_levenberg_marquardt: Some(bad), ..ok.clone() };
        assert!(field(c).contains("first_sample_levenberg_marquardt"));
    }
}

/// The continuation's initial states lie on the segment from the reference to `x0` at
/// `α = j/m`, in order, and the last is `x0` bit for bit (one step: `x0` alone).
#[test]
fn continuation_states_run_from_the_reference_to_the_state() {
    let x_ref = [0.0, 1.0, -2.0, 0.5];
    let x0 = [1.5, 0.7, -2.0, 0.1 + 0.2];
    assert_eq!(super::continuation_states(&x_ref, &x0, 1), vec![x0.to_vec()]);
    let m = 4;
    let states = super::continuation_states(&x_ref, &x0, m);
    assert_eq!(states.len(), m);
    assert_eq!(states[m - 1], x0.to_vec());
    let mut last = 0.0;
    for (j, s) in states.iter().enumerate() {
        let alpha = (j + 1) as f64 / m as f64;
        for i in 0..x0.len() {
            let want = x_ref[i] + alpha * (x0[i] - x_ref[i]);
            assert!((s[i] - want).abs() <= 1e-15, "step {j} entry {i}: {} vs {want}", s[i]);
        }
        let d: f64 = s.iter().zip(&x_ref).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt();
        assert!(d > last, "step {j}: distance {d} not beyond {last}");
        last = d;
    }
}

/// The first sample of a fast 2D rotation (its SQP does not converge in 2 iterations from
/// the linear MPC plan).
fn fast_2d_first_sample(c: &ControllerSettings) -> SampleReport {
    first_sample_2d(c, 1.5)
}

/// The first sample of a 2D rotation at the rate `rate`.
fn first_sample_2d(c: &ControllerSettings, rate: f64) -> SampleReport {
    let setup = setup_2d();
    let s = &setup.scenario;
    let mut x0: Vec<f64> = setup.weights.x_ref.iter().copied().collect();
    x0[0] = rate;
    let model = RomDynamics::new(&setup.rom).unwrap();
    assert_eq!(model.nx(), x0.len());
    Controller::new(model, &setup.weights, &s.mpc, c).unwrap().step(0.0, &x0).unwrap()
}

fn fast_2d_base() -> ControllerSettings {
    ControllerSettings {
        max_iterations: 2,
        retry_relaxation: None,
        fallback_to_lmpc: false,
        ..ControllerSettings::full_sqp()
    }
}

/// The continuation solves the same first-sample problem: to convergence it reaches the plan
/// that the first-sample iterations without it reach, and it spends iterations on every step
/// (each intermediate problem differs from the previous one in its initial state).
#[test]
fn continuation_reaches_the_same_first_plan() {
    let base = ControllerSettings { first_sample_iterations: Some(40), ..fast_2d_base() };
    let direct = first_sample_2d(&base, 0.75);
    let homotopy =
        first_sample_2d(&ControllerSettings { first_sample_continuation: 3, ..base.clone() }, 0.75);
    assert_eq!(direct.status, "Solved", "{direct:?}");
    assert_eq!(homotopy.status, "Solved", "{homotopy:?}");
    assert!(homotopy.iterations > 3, "{homotopy:?}");
    // both within the KKT tolerance 1e-4 of the same KKT point: the controls agree to that
    // over the control weight's curvature (k_u = 0.1), the costs to second order
    for (a, b) in direct.u.iter().zip(&homotopy.u) {
        assert!((a - b).abs() <= 1e-3, "u0 {a} vs {b}");
    }
    assert!((direct.cost - homotopy.cost).abs() <= 1e-5, "{} vs {}", direct.cost, homotopy.cost);
}

/// The first-sample LM term reaches the first sample's extra iterations only: equal to the
/// first attempt's term it changes nothing (same bits), and a large one damps the steps of a
/// short first-sample budget, leaving the plan farther from the KKT point.
#[test]
fn first_sample_levenberg_marquardt_damps_the_first_iterations() {
    let base = ControllerSettings {
        first_sample_iterations: Some(4),
        levenberg_marquardt: 1e-3,
        ..fast_2d_base()
    };
    let plain = fast_2d_first_sample(&base);
    let same = fast_2d_first_sample(&ControllerSettings {
        first_sample_levenberg_marquardt: Some(1e-3),
        ..base.clone()
    });
    let key = |r: &SampleReport| (r.u.clone(), r.kkt.to_bits(), r.cost.to_bits(), r.iterations);
    assert_eq!(key(&plain), key(&same));
    let heavy = fast_2d_first_sample(&ControllerSettings {
        first_sample_levenberg_marquardt: Some(1e3),
        ..base.clone()
    });
    assert!(heavy.kkt > plain.kkt, "{} !> {}", heavy.kkt, plain.kkt);
}
