//! The first sample of the NMPC: there is no shifted plan to start from, so its start is
//! built — the initial guess ([`InitialGuess`]), the extra iterations
//! ([`ControllerSettings::first_sample_iterations`]) and the continuation in the initial state
//! ([`ControllerSettings::first_sample_continuation`]).
//!
//! Continuation (homotopy): the first sample's OCP is solved for a family of initial states
//! between the reference and the measured state,
//!
//! ```text
//!   x0(α) = x_r + α (x0 − x_r),   α_j = j/m,  j = 1…m   (α_m = 1: the measured state),
//! ```
//!
//! each solve starting from the previous one's solution. The OCP's solution depends smoothly
//! on `x0` where it is regular, so a solution for `α_j` is a start close to that for
//! `α_{j+1}` when the steps are small, while the SQP from a guess built directly for a large
//! disturbance may stall far from a KKT point (docs/mpc.md, "Toward ω0 = 1.5").

use super::{copy_plan, plan_finite, Controller, ControllerSettings};
use crate::error::Result;
use nalgebra::DVector;
use ocp_transcription::{Dynamics, SqpSolver};
use serde::{Deserialize, Serialize};

#[cfg(test)]
mod tests;

/// Initial guess of the first sample's NMPC solve ([`ControllerSettings::first_sample_guess`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InitialGuess {
    /// The linear MPC plan (its QP on the model linearised at the reference): a trajectory
    /// of the linearised model, consistent with the measured state.
    #[default]
    LinearMpc,
    /// Shooting nodes on the line from the measured state to the reference, reached at the
    /// end of the horizon, `s_k = x_r,k + (1 − k/Nc)(x0 − x_r,k)`, and the reference controls
    /// (Bock's principle: multiple shooting may start from nodes near the wanted trajectory,
    /// not on a rollout; the SQP closes the defects). The plan's nodes stay near the
    /// reference, where the model is mildly nonlinear, instead of following a prediction of
    /// the uncontrolled motion away from it.
    Decay,
}

/// Sets `solver`'s iterate to the [`InitialGuess::Decay`] guess from `x0`.
pub(crate) fn decay_guess<D: Dynamics>(solver: &mut SqpSolver<D>, x0: &[f64]) {
    let n = solver.controls().len();
    let ocp = solver.ocp();
    let refs: Vec<DVector<f64>> = (0..=n)
        .map(|k| ocp.x_ref_nodes.get(k).cloned().unwrap_or_else(|| ocp.x_ref.clone()))
        .collect();
    let u_ref = ocp.u_ref.clone();
    for (k, (s, r)) in solver.states_mut().iter_mut().zip(&refs).enumerate() {
        let w = 1.0 - k as f64 / n as f64;
        for (i, v) in s.iter_mut().enumerate() {
            *v = r[i] + w * (x0[i] - r[i]);
        }
    }
    for u in solver.controls_mut() {
        u.copy_from(&u_ref);
    }
}

/// The initial states of the continuation with `steps` steps from the reference `x_ref`
/// (the plan's first node reference) to `x0`: `x_r + (j/steps)(x0 − x_r)` for
/// `j = 1…steps`; the last one is `x0` itself (bit for bit).
pub(crate) fn continuation_states(x_ref: &[f64], x0: &[f64], steps: usize) -> Vec<Vec<f64>> {
    (1..=steps)
        .map(|j| {
            if j == steps {
                return x0.to_vec();
            }
            let alpha = j as f64 / steps as f64;
            x_ref.iter().zip(x0).map(|(r, x)| r + alpha * (x - r)).collect()
        })
        .collect()
}

impl<D: Dynamics + Clone> Controller<D> {
    /// The first sample's start: solves the linear MPC (at the first continuation state),
    /// sets the initial guess, runs the first-sample iterations along the continuation
    /// ([`ControllerSettings::first_sample_continuation`]) and leaves their last usable
    /// iterate in the NMPC solver for the sample's ordinary solve. Returns the iterations
    /// spent.
    pub(super) fn first_sample_start(&mut self, x0: &[f64], shift: f64) -> Result<usize> {
        let settings: &ControllerSettings = &self.settings;
        let steps = if self.initial.is_some() { settings.first_sample_continuation } else { 1 };
        let guess = settings.first_sample_guess;
        let x_ref: Vec<f64> = {
            let ocp = self.lmpc.ocp();
            ocp.x_ref_nodes.first().unwrap_or(&ocp.x_ref).iter().copied().collect()
        };
        let states = continuation_states(&x_ref, x0, steps);
        let start = &states[0];
        // the guess for the first continuation state
        self.solve_lmpc(start, shift)?;
        self.nmpc_from_lmpc();
        if guess == InitialGuess::Decay {
            let target = match self.initial.as_mut() {
                Some(i) => Some(i),
                None => self.nmpc.as_mut(),
            };
            if let Some(solver) = target {
                decay_guess(solver, start);
            }
        } else if let Some(i) = self.initial.as_mut() {
            copy_plan(&self.lmpc, i);
        }
        let mut iterations = 0;
        if let (Some(i), Some(n)) = (self.initial.as_mut(), self.nmpc.as_mut()) {
            for (j, xj) in states.iter().enumerate() {
                // more iterations from the guess, or from the previous step's solution; the
                // NMPC goes on from where the last usable one ended
                if j > 0 {
                    copy_plan(n, i);
                }
                let (st, _) = i.solve_with_fallback_starts(xj)?;
                iterations += st.iterations;
                if st.status.has_iterate() && plan_finite(i) {
                    copy_plan(i, n);
                }
            }
        }
        Ok(iterations)
    }
}
