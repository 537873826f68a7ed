//! Per-node state references (`Ocp::x_ref_nodes`): a reference that moves over the horizon.

use crate::sqp::{lqr_problem, riccati};
use nalgebra::DVector;
use ocp_transcription::{Integrator, QpForm, SqpMode, SqpSettings, SqpSolver, SqpStatus};

/// Per-node references equal to `x_r` at every node give the constant-reference solve, bit
/// for bit; an empty list returns to it.
#[test]
fn constant_node_references_are_the_constant_reference() {
    let (model, mut ocp) = lqr_problem();
    ocp.x_ref = DVector::from_vec(vec![0.1, 0.0, -0.2, 0.0, 0.05, 0.0]);
    let x0 = [0.5, -0.3, 0.2, 0.0, 0.4, -0.1];
    let settings = SqpSettings { mode: SqpMode::Sqp, ..SqpSettings::default() };
    let mut plain = SqpSolver::new(&model, ocp.clone(), settings.clone()).unwrap();
    let a = plain.solve(&x0).unwrap();
    let mut nodes = SqpSolver::new(&model, ocp.clone(), settings.clone()).unwrap();
    let same: Vec<Vec<f64>> = vec![ocp.x_ref.iter().copied().collect(); ocp.intervals + 1];
    nodes.set_node_references(&same).unwrap();
    let b = nodes.solve(&x0).unwrap();
    assert_eq!(a.cost.to_bits(), b.cost.to_bits());
    assert_eq!(plain.states(), nodes.states());
    assert_eq!(plain.controls(), nodes.controls());
    nodes.set_node_references(&[]).unwrap();
    assert!(nodes.ocp().x_ref_nodes.is_empty());
    // dimension and finiteness are checked
    assert!(nodes.set_node_references(&same[1..]).is_err());
    let mut bad = same.clone();
    bad[3][2] = f64::NAN;
    assert!(nodes.set_node_references(&bad).is_err());
    let mut o = ocp.clone();
    o.x_ref_nodes = vec![ocp.x_ref.clone(); ocp.intervals];
    assert!(o.validate().is_err());
}

/// A moving reference on a linear model: with the reference a free response `y_k` of the
/// discrete model, the optimal plan from `x0` is `y_k + x_k` with `(x_k, u_k)` the Riccati
/// (zero-reference) solution from `x0 − y_0` (the problem is linear–quadratic in the deviation
/// from `y`); from `x0 = y_0` the plan is `y` itself at zero cost. A constant reference gives
/// neither.
#[test]
fn moving_reference_is_tracked_exactly_on_a_linear_model() {
    let (model, ocp) = lqr_problem();
    let settings = SqpSettings { mode: SqpMode::Sqp, ..SqpSettings::default() };
    let n = ocp.intervals;
    let mut int = Integrator::new(&model, &settings.integrator, ocp.interval()).unwrap();
    let mut y = vec![vec![0.8, -0.4, 0.3, 0.2, 0.0, -0.5]];
    for k in 0..n {
        let mut next = vec![0.0; 6];
        int.integrate(&model, &y[k], &[0.0, 0.0], &mut next).unwrap();
        y.push(next);
    }
    for form in [QpForm::CondensedClarabel, QpForm::SparseClarabel] {
        let s = SqpSettings { qp_form: form, ..settings.clone() };
        let mut solver = SqpSolver::new(&model, ocp.clone(), s).unwrap();
        solver.set_node_references(&y).unwrap();
        // from y_0: the reference itself, cost 0
        let st = solver.solve(&y[0]).unwrap();
        assert_eq!(st.status, SqpStatus::Solved, "{form:?}");
        assert!(st.cost.abs() < 1e-14, "{form:?}: cost {:e}", st.cost);
        for k in 0..=n {
            let d = (&solver.states()[k] - DVector::from_column_slice(&y[k])).amax();
            assert!(d < 1e-9, "{form:?}: node {k} off the reference by {d:e}");
        }
        // from x0: reference + Riccati deviation
        let x0 = DVector::from_vec(vec![0.5, -0.3, 0.2, 0.0, 0.4, -0.1]);
        let dev = &x0 - DVector::from_column_slice(&y[0]);
        let (xs, us) = riccati(&model, &ocp, &settings.integrator, &dev);
        let st = solver.solve(x0.as_slice()).unwrap();
        assert_eq!(st.status, SqpStatus::Solved, "{form:?}");
        let mut err = 0.0_f64;
        for k in 0..n {
            err = err.max((&solver.controls()[k] - &us[k]).amax());
            let expect = DVector::from_column_slice(&y[k + 1]) + &xs[k + 1];
            err = err.max((&solver.states()[k + 1] - expect).amax());
        }
        assert!(err < 1e-8, "{form:?}: deviation from reference + Riccati {err:e}");
        // the cost the solver reports is the problem's own (per-node) cost
        let j = solver.ocp().cost(solver.states(), solver.controls()).unwrap();
        assert!((j - st.cost).abs() <= 1e-12 * (1.0 + j.abs()), "{form:?}: {j} vs {}", st.cost);
        // with the constant reference y_0 the plan does not follow y
        let mut constant = SqpSolver::new(&model, ocp.clone(), settings.clone()).unwrap();
        constant.set_references(&y[0], &[0.0, 0.0]).unwrap();
        constant.solve(&y[0]).unwrap();
        let off = (&constant.states()[n] - DVector::from_column_slice(&y[n])).amax();
        assert!(off > 1e-2, "{form:?}: a constant reference should not track y ({off:e})");
    }
}
