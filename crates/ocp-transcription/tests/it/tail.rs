//! Coarser substeps at the end of the horizon (`IntegratorSettings::tail`): the tail intervals
//! run exactly the integrator with the tail's count, the counts stay per interval through a
//! solve, and the settings are checked.

use nalgebra::DMatrix;
use ocp_transcription::samples::ModalLike;
use ocp_transcription::{
    Dynamics, Globalisation, Integrator, IntegratorKind, IntegratorSettings, Ocp, QpForm, SqpMode,
    SqpSettings, SqpSolver, SqpStatus, TailSubsteps,
};

fn tail_settings(kind: IntegratorKind) -> IntegratorSettings {
    IntegratorSettings {
        tail: Some(TailSubsteps { from_interval: 4, substeps: 2 }),
        ..IntegratorSettings::new(kind, 5)
    }
}

fn ocp(m: &ModalLike) -> Ocp {
    let (nx, nu) = (m.nx(), m.nu());
    let mut o = Ocp::new(nx, nu, 1.5, 6).unwrap();
    o.q = DMatrix::identity(nx, nx);
    o.r = DMatrix::identity(nu, nu) * 0.1;
    o
}

/// A rollout through the horizon integrates intervals 0–3 with 5 substeps and 4–5 with 2: each
/// node equals, bit for bit, a stand-alone integrator of that count on the previous node.
#[test]
fn tail_intervals_run_the_integrator_with_the_tail_count() {
    let m = ModalLike::rom_like(21, 3, 120.0, 0.1, 7).unwrap();
    let x0 = m.rotating_state(1.0).unwrap();
    let u = [0.3, -0.2, 0.1];
    // (not RK4: two explicit substeps of 0.125 s are unstable at this model's 120 rad/s)
    for kind in [IntegratorKind::ImplicitMidpoint, IntegratorKind::LawsonRk4] {
        let settings = SqpSettings { integrator: tail_settings(kind), ..SqpSettings::default() };
        let mut s = SqpSolver::new(m.clone(), ocp(&m), settings).unwrap();
        s.initialize_by_simulation(&x0, &u).unwrap();
        assert_eq!(s.substep_counts(), &[5, 5, 5, 5, 2, 2], "{kind:?}");
        let dt = s.ocp().interval();
        for k in 0..6 {
            let n = if k < 4 { 5 } else { 2 };
            let mut int = Integrator::new(&m, &IntegratorSettings::new(kind, n), dt).unwrap();
            let mut next = vec![0.0; m.nx()];
            int.integrate(&m, s.states()[k].as_slice(), &u, &mut next).unwrap();
            assert_eq!(next.as_slice(), s.states()[k + 1].as_slice(), "{kind:?} interval {k}");
        }
        // the tail's coarser steps move the far nodes (a different map, not a relabelling)
        let mut fine = SqpSolver::new(
            m.clone(),
            ocp(&m),
            SqpSettings { integrator: IntegratorSettings::new(kind, 5), ..SqpSettings::default() },
        )
        .unwrap();
        fine.initialize_by_simulation(&x0, &u).unwrap();
        assert_eq!(fine.states()[4], s.states()[4], "{kind:?}");
        assert_ne!(fine.states()[6], s.states()[6], "{kind:?}");
    }
}

/// Real-time iterations with a tail, shifted between samples: the counts stay those of the
/// interval index, and the sequential and parallel interval sweeps give the same bits.
#[test]
fn real_time_iterations_with_a_tail() {
    let m = ModalLike::rom_like(21, 3, 120.0, 0.1, 7).unwrap();
    let run = |parallel: bool| {
        let settings = SqpSettings {
            mode: SqpMode::RealTimeIteration,
            qp_form: QpForm::CondensedDense,
            globalisation: Globalisation::merit(),
            integrator: tail_settings(IntegratorKind::ImplicitMidpoint),
            parallel_intervals: parallel,
            ..SqpSettings::default()
        };
        let mut s = SqpSolver::new(m.clone(), ocp(&m), settings).unwrap();
        let mut x = m.rotating_state(1.5).unwrap();
        s.initialize_by_simulation(&x, &[0.0; 3]).unwrap();
        let mut plans = Vec::new();
        for _ in 0..4 {
            let st = s.solve(&x).unwrap();
            assert_eq!(st.status, SqpStatus::RealTimeIteration);
            assert_eq!(s.substep_counts(), &[5, 5, 5, 5, 2, 2]);
            plans.push((s.states().to_vec(), s.controls().to_vec()));
            x = s.states()[1].iter().copied().collect();
            s.shift(1);
        }
        plans
    };
    assert_eq!(run(false), run(true));
}

/// The checks name the field: a tail from interval 0, with no substeps, with adaptive counts,
/// or past the horizon.
#[test]
fn tail_settings_are_validated() {
    let base = IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 4);
    let with = |from_interval, substeps| IntegratorSettings {
        tail: Some(TailSubsteps { from_interval, substeps }),
        ..base.clone()
    };
    assert!(with(0, 2).validate().unwrap_err().to_string().contains("tail.from_interval"));
    assert!(with(3, 0).validate().unwrap_err().to_string().contains("tail.substeps"));
    let adaptive = IntegratorSettings { adaptive: Some(Default::default()), ..with(3, 2) };
    let adaptive = IntegratorSettings { kind: IntegratorKind::Rk4, substeps: 8, ..adaptive };
    assert!(adaptive.validate().unwrap_err().to_string().contains("integrator.tail"));
    assert_eq!((0..5).map(|k| with(3, 2).substeps_of(k)).collect::<Vec<_>>(), [4, 4, 4, 2, 2]);
    let m = ModalLike::rom_like(21, 3, 120.0, 0.1, 7).unwrap();
    let past = SqpSettings { integrator: with(6, 2), ..SqpSettings::default() };
    let e = SqpSolver::new(m.clone(), ocp(&m), past).err().unwrap().to_string();
    assert!(e.contains("tail.from_interval") && e.contains("6 intervals"), "{e}");
}
