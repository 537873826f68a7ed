//! Warm-started implicit midpoint trials (`Integrator::integrate_near`): the same end state
//! as Newton from scratch to the Newton tolerance, with fewer right-hand sides and no
//! Jacobian when the trial is near the recorded integration.

use super::simplified_newton::{max_rel, stiff_case, Counting};
use nalgebra::DMatrix;
use ocp_transcription::{Dynamics, Integrator, IntegratorKind, IntegratorSettings};

/// A line-search-like direction: every state and control moved, by 5 % of the state's scale.
fn direction(x: &[f64], nu: usize) -> (Vec<f64>, Vec<f64>) {
    let scale = x.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let dx = (0..x.len()).map(|i| 0.05 * scale * ((i as f64) * 1.3 + 0.4).sin()).collect();
    let du = (0..nu).map(|c| 0.3 * ((c as f64) * 2.1 + 0.2).cos()).collect();
    (dx, du)
}

fn at(x: &[f64], dx: &[f64], t: f64) -> Vec<f64> {
    x.iter().zip(dx).map(|(a, b)| a + t * b).collect()
}

/// The trial states along a step from the recorded point agree with a from-scratch
/// integration to 1e-12 (relative) at every step length, in the scene's regime (4 substeps,
/// `h ω` up to 11) and with 16 substeps, and cost fewer right-hand sides: with the factor
/// refreshed by the contraction rule only, no Jacobian at all; with the refresh after the
/// first step (default), no more Jacobians than from scratch.
#[test]
fn a_warm_started_trial_agrees_with_newton_from_scratch_and_costs_less() {
    let (m, x, u) = stiff_case();
    let m = Counting::new(m);
    let (nx, nu) = (m.nx(), m.nu());
    let (dx, du) = direction(&x, nu);
    for refresh in [false, true] {
        for n in [4, 16] {
            let settings = IntegratorSettings {
                refresh_after_first_step: refresh,
                ..IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, n)
            };
            let mut int = Integrator::new(&m, &settings, 0.25).unwrap();
            let mut record = int.new_record();
            let (mut xe, mut a, mut b) =
                (vec![0.0; nx], DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
            int.integrate_with_sensitivities_recorded(
                &m,
                &x,
                &u,
                &mut xe,
                &mut a,
                &mut b,
                &mut record,
            )
            .unwrap();
            assert!(record.is_recorded());
            let (mut cold_rhs, mut warm_rhs) = (0, 0);
            for t in [1.0, 0.5, 0.25, 0.05] {
                let (xt, ut) = (at(&x, &dx, t), at(&u, &du, t));
                let (mut cold, mut warm) = (vec![0.0; nx], vec![0.0; nx]);
                m.take();
                int.integrate(&m, &xt, &ut, &mut cold).unwrap();
                let c = m.take();
                int.integrate_near(&m, &xt, &ut, &mut warm, &mut record).unwrap();
                let w = m.take();
                let case = format!("refresh {refresh}, n = {n}, t = {t}: warm {w:?}, cold {c:?}");
                let d = max_rel(&cold, &warm);
                assert!(d <= 1e-12, "{case}: warm vs cold {d:e}");
                // the trial moved the end state by far more than the tolerance
                assert!(max_rel(&cold, &xe) > 1e-6, "{case}");
                if refresh {
                    assert!(w.1 <= c.1, "{case}");
                } else {
                    assert_eq!(w.1, 0, "{case}");
                }
                assert!(w.0 <= c.0 && w.0 + w.1 < c.0 + c.1, "{case}");
                cold_rhs += c.0;
                warm_rhs += w.0;
            }
            // over the four step lengths
            assert!(warm_rhs < cold_rhs, "refresh {refresh}, n = {n}: rhs {cold_rhs} / {warm_rhs}");
        }
    }
}

/// Recording does not change the integration (same bits), and a record that does not match
/// (none held, another substep count) leaves `integrate_near` equal to `integrate`.
#[test]
fn recording_is_transparent_and_a_mismatched_record_is_ignored() {
    let (m, x, u) = stiff_case();
    let (nx, nu) = (m.nx(), m.nu());
    let settings = IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 4);
    let mut int = Integrator::new(&m, &settings, 0.25).unwrap();
    let mut record = int.new_record();
    let mut plain = (vec![0.0; nx], DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
    int.integrate_with_sensitivities(&m, &x, &u, &mut plain.0, &mut plain.1, &mut plain.2).unwrap();
    let mut rec = (vec![0.0; nx], DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
    int.integrate_with_sensitivities_recorded(
        &m,
        &x,
        &u,
        &mut rec.0,
        &mut rec.1,
        &mut rec.2,
        &mut record,
    )
    .unwrap();
    assert_eq!(plain, rec);
    let (dx, du) = direction(&x, nu);
    let (xt, ut) = (at(&x, &dx, 0.5), at(&u, &du, 0.5));
    let mut cold = vec![0.0; nx];
    int.integrate(&m, &xt, &ut, &mut cold).unwrap();
    // another substep count: the record is not used
    let mut other =
        Integrator::new(&m, &IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, 8), 0.25)
            .unwrap();
    let (mut a, mut b) = (vec![0.0; nx], vec![0.0; nx]);
    other.integrate(&m, &xt, &ut, &mut a).unwrap();
    other.integrate_near(&m, &xt, &ut, &mut b, &mut record).unwrap();
    assert_eq!(a, b);
    // a cleared record
    record.clear();
    let mut c = vec![0.0; nx];
    int.integrate_near(&m, &xt, &ut, &mut c, &mut record).unwrap();
    assert_eq!(c, cold);
    // a record of another model's size is an error
    let small = Integrator::new(
        &ocp_transcription::samples::ModalLike::new(9, 2, 10.0, 1.0, 3).unwrap(),
        &settings,
        0.25,
    )
    .unwrap();
    assert!(int.integrate_near(&m, &xt, &ut, &mut c, &mut small.new_record()).is_err());
}

/// A linearisation from exactly the data of the record's last trial (the accepted trial of a
/// real-time iteration, shifted) starts each substep at the trial's converged midpoint: one
/// evaluation with the Jacobians per substep, the same end state and sensitivities as from
/// scratch to the Newton tolerance. Data that differ in one bit are integrated as before.
#[test]
fn a_linearisation_at_the_last_trial_starts_at_its_midpoints() {
    let (m, x, u) = stiff_case();
    let m = Counting::new(m);
    let (nx, nu) = (m.nx(), m.nu());
    let (dx, du) = direction(&x, nu);
    for n in [4, 16] {
        let settings = IntegratorSettings::new(IntegratorKind::ImplicitMidpoint, n);
        let mut int = Integrator::new(&m, &settings, 0.25).unwrap();
        let mut record = int.new_record();
        let out = |int: &mut Integrator, x: &[f64], u: &[f64], r: &mut _| {
            let mut o = (vec![0.0; nx], DMatrix::zeros(nx, nx), DMatrix::zeros(nx, nu));
            int.integrate_with_sensitivities_recorded(&m, x, u, &mut o.0, &mut o.1, &mut o.2, r)
                .unwrap();
            (o, m.take())
        };
        out(&mut int, &x, &u, &mut record);
        let (xt, ut) = (at(&x, &dx, 0.5), at(&u, &du, 0.5));
        let mut trial = vec![0.0; nx];
        int.integrate_near(&m, &xt, &ut, &mut trial, &mut record).unwrap();
        m.take();
        // from scratch (a record without the trial's midpoints)
        let mut fresh = int.new_record();
        let (cold, cold_count) = out(&mut int, &xt, &ut, &mut fresh);
        let (warm, warm_count) = out(&mut int, &xt, &ut, &mut record);
        let case = format!("n = {n}: warm {warm_count:?}, cold {cold_count:?}");
        assert_eq!(warm_count, (n, n), "{case}");
        assert!(cold_count.0 + cold_count.1 > 2 * n, "{case}");
        let d = [max_rel(&cold.0, &warm.0), max_rel(cold.1.as_slice(), warm.1.as_slice())];
        let d = [d[0], d[1], max_rel(cold.2.as_slice(), warm.2.as_slice())];
        assert!(d[0] <= 1e-12 && d[1] <= 1e-9 && d[2] <= 1e-9, "{case}: {d:?}");
        // the trial's end state is the linearisation's, to the tolerance
        assert!(max_rel(&trial, &warm.0) <= 1e-12, "{case}");
        // one bit of one start entry changed: integrated from scratch
        let mut xb = xt.clone();
        xb[0] = f64::from_bits(xb[0].to_bits() + 1);
        int.integrate_near(&m, &xt, &ut, &mut trial, &mut record).unwrap();
        m.take();
        let (_, moved) = out(&mut int, &xb, &ut, &mut record);
        assert_eq!(moved, cold_count, "{case}: one bit off");
    }
}
