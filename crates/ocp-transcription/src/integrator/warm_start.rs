//! Warm starts of the implicit midpoint rule's Newton iterations near a linearisation.
//!
//! An integration with sensitivities from `(x0, u)` records, for each substep `j`, its start
//! `x_j`, the converged midpoint `m_j`, `F_u,j = ∂f/∂u(m_j, u)` and the factorised Newton
//! matrix `M_j = I − h/2 ∂f/∂x(m_j, u)` (all of them computed for the sensitivities anyway).
//! A later integration without sensitivities from a nearby point `(x0', u')` (a line-search
//! trial) starts substep `j`'s Newton iteration from the first-order predictor
//!
//! `m_j' = m_j + M_j⁻¹ ((x_j' − x_j) + h/2 F_u,j (u' − u))`,
//!
//! the Newton step for the trial's residual `r(m) = m − x_j' − h/2 f(m, u')` from the base
//! midpoint, linearised in the data (the base residual vanishes there), with `x_j'` the
//! trial's own substep start. It iterates with `M_j` as its simplified Newton matrix (refreshed
//! at the iterate, as from scratch, when the contraction is slow). The convergence test is
//! the one of an iteration from scratch, so the trial's states agree with it to the Newton
//! tolerance: only the starting point and the matrix differ. The predictor's error is
//! second order in the distance to the base, where the start from scratch (the substep's
//! start or the previous substep's slope) is first order in the step size `h`.

use super::{Integrator, IntegratorKind};
use crate::error::{check_dim, Result};
use nalgebra::DMatrix;

/// The converged substeps of one implicit-midpoint interval integration with sensitivities
/// ([`Integrator::integrate_with_sensitivities_recorded`]): the warm start of later
/// integrations near it ([`Integrator::integrate_near`]). Allocated once
/// ([`Integrator::new_record`]); recording overwrites it without allocating. Empty for the
/// explicit methods (nothing to warm-start).
#[derive(Clone, Debug)]
pub struct MidpointRecord {
    nx: usize,
    nu: usize,
    /// Substeps of the recorded integration; 0 when there is none (a failed or explicit one).
    substeps: usize,
    h: f64,
    u: Vec<f64>,
    x: Vec<Vec<f64>>,
    m: Vec<Vec<f64>>,
    fu: Vec<DMatrix<f64>>,
    lu: Vec<DMatrix<f64>>,
    perm: Vec<Vec<usize>>,
    perm_inv: Vec<Vec<usize>>,
    /// The last integration started from this record ([`Integrator::integrate_near`]): its
    /// substeps (0 when none), step, control, start and converged midpoints. A later
    /// integration with sensitivities from exactly the same data starts each substep's Newton
    /// iteration there.
    path_substeps: usize,
    path_h: f64,
    path_u: Vec<f64>,
    path_x0: Vec<f64>,
    path_m: Vec<Vec<f64>>,
}

impl MidpointRecord {
    /// Whether a recorded integration is held (the last recording succeeded).
    pub fn is_recorded(&self) -> bool {
        self.substeps > 0
    }

    /// Forgets the recorded integration and the midpoints of the last integration started
    /// from it.
    pub fn clear(&mut self) {
        self.substeps = 0;
        self.path_substeps = 0;
    }

    /// Whether the midpoints of the last integration started from this record are those of
    /// an integration from `x0` with `u`, `substeps` steps of `h` (the same data to the bit).
    fn path_matches(&self, x0: &[f64], u: &[f64], h: f64, substeps: usize) -> bool {
        self.path_substeps == substeps
            && substeps > 0
            && self.path_h == h
            && self.path_u == u
            && self.path_x0 == x0
    }
}

/// What an interval integration does with a [`MidpointRecord`].
pub(super) enum Warm<'a> {
    /// Nothing: Newton from scratch.
    Cold,
    /// Records its converged substeps (an integration with sensitivities); with `reuse`, each
    /// substep's Newton iteration starts at the midpoint of the record's last integration
    /// from the same data (converged there: one evaluation, with the Jacobians).
    Record { record: &'a mut MidpointRecord, reuse: bool },
    /// Starts each substep's Newton iteration from the record's predictor, and keeps the
    /// converged midpoints in the record.
    Start(&'a mut MidpointRecord),
}

impl Integrator {
    /// A record for [`Integrator::integrate_with_sensitivities_recorded`] sized for this
    /// integrator (every substep count it can run); empty for the explicit methods.
    pub fn new_record(&self) -> MidpointRecord {
        let (nx, nu) = (self.nx, self.nu);
        let n = if self.kind == IntegratorKind::ImplicitMidpoint { self.range.1 } else { 0 };
        MidpointRecord {
            nx,
            nu,
            substeps: 0,
            h: 0.0,
            u: vec![0.0; nu],
            x: vec![vec![0.0; nx]; n],
            m: vec![vec![0.0; nx]; n],
            fu: vec![DMatrix::zeros(nx, nu); n],
            lu: vec![DMatrix::zeros(nx, nx); n],
            perm: vec![vec![0; nx]; n],
            perm_inv: vec![vec![0; nx]; n],
            path_substeps: 0,
            path_h: 0.0,
            path_u: vec![0.0; nu],
            path_x0: vec![0.0; nx],
            path_m: vec![vec![0.0; nx]; n],
        }
    }

    fn check_record(&self, record: &MidpointRecord) -> Result<()> {
        check_dim("record nx", self.nx, record.nx)?;
        check_dim("record nu", self.nu, record.nu)
    }

    /// [`Integrator::integrate_with_sensitivities`], recording the converged substeps in
    /// `record` (implicit midpoint; the record is cleared first and holds this integration
    /// only when it succeeds). When the record holds the midpoints of an
    /// [`Integrator::integrate_near`] from exactly `(x0, u)` (the same bits, e.g. the accepted
    /// line-search trial of the previous real-time iteration, shifted), each substep's Newton
    /// iteration starts at them: they passed the convergence test there, so the substep costs
    /// one evaluation with the Jacobians instead of an iteration; the test is repeated, so a
    /// midpoint that does not pass it is iterated on as usual. Otherwise the result is the same
    /// to the bit as without recording.
    #[allow(clippy::too_many_arguments)]
    pub fn integrate_with_sensitivities_recorded<D: crate::Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        x_end: &mut [f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
        record: &mut MidpointRecord,
    ) -> Result<()> {
        self.check_args(x0, u, x_end)?;
        self.check_record(record)?;
        let reuse = self.kind == IntegratorKind::ImplicitMidpoint
            && record.path_matches(x0, u, self.h, self.substeps);
        record.substeps = 0;
        self.sensitivities_warm(model, x0, u, x_end, a, b, Warm::Record { record, reuse })
    }

    /// `x_end = Φ(x0, u)` near the integration held by `record` (implicit midpoint): each
    /// substep's Newton iteration starts from the record's first-order predictor with the
    /// record's Newton matrix (module docs of `integrator::warm_start`; same convergence test
    /// as [`Integrator::integrate`], so the same end state to the Newton tolerance); the
    /// converged midpoints are kept in the record for a later
    /// [`Integrator::integrate_with_sensitivities_recorded`] from the same data. Without a
    /// matching record (none held, another substep count, an explicit method) this is
    /// [`Integrator::integrate`].
    pub fn integrate_near<D: crate::Dynamics + ?Sized>(
        &mut self,
        model: &D,
        x0: &[f64],
        u: &[f64],
        x_end: &mut [f64],
        record: &mut MidpointRecord,
    ) -> Result<()> {
        self.check_args(x0, u, x_end)?;
        self.check_record(record)?;
        record.path_substeps = 0;
        let warm = if self.kind == IntegratorKind::ImplicitMidpoint
            && record.substeps == self.substeps
            && record.h == self.h
        {
            Warm::Start(record)
        } else {
            Warm::Cold
        };
        self.run_warm(model, x0, u, false, false, warm)?;
        x_end.copy_from_slice(&self.x);
        Ok(())
    }

    /// Stores substep `j`'s start (still in `x`), converged midpoint, `∂f/∂u` and factor
    /// (the sensitivity pass's, at the midpoint) in `record`.
    pub(super) fn record_substep(&self, record: &mut MidpointRecord, j: usize) {
        record.x[j].copy_from_slice(&self.x);
        record.m[j].copy_from_slice(&self.xs);
        record.fu[j].copy_from(&self.fu);
        record.lu[j].copy_from(&self.lu);
        record.perm[j].copy_from_slice(&self.perm);
        record.perm_inv[j].copy_from_slice(&self.perm_inv);
    }

    /// Keeps substep `j`'s converged midpoint (still in `xs`) in `record`'s path.
    pub(super) fn record_path_midpoint(&self, record: &mut MidpointRecord, j: usize) {
        record.path_m[j].copy_from_slice(&self.xs);
    }

    /// Marks `record`'s path as the integration just finished from `x0` with control `u`.
    pub(super) fn finish_path(&self, record: &mut MidpointRecord, x0: &[f64], u: &[f64]) {
        record.path_u.copy_from_slice(u);
        record.path_x0.copy_from_slice(x0);
        record.path_h = self.h;
        record.path_substeps = self.substeps;
    }

    /// Substep `j`'s midpoint of `record`'s path.
    pub(super) fn path_midpoint(record: &MidpointRecord, j: usize) -> &[f64] {
        &record.path_m[j]
    }

    /// Marks `record` as holding the integration just finished with control `u`.
    pub(super) fn finish_record(&self, record: &mut MidpointRecord, u: &[f64]) {
        if self.kind == IntegratorKind::ImplicitMidpoint {
            record.u.copy_from_slice(u);
            record.h = self.h;
            record.substeps = self.substeps;
        }
    }

    /// Loads substep `j`'s Newton matrix from `record` and sets the Newton start `xs` to the
    /// predictor `m_j + M_j⁻¹ ((x − x_j) + h/2 F_u,j (u − u_rec))`.
    pub(super) fn predict_midpoint(&mut self, record: &MidpointRecord, j: usize, u: &[f64]) {
        let nx = self.nx;
        self.lu.copy_from(&record.lu[j]);
        self.perm.copy_from_slice(&record.perm[j]);
        self.perm_inv.copy_from_slice(&record.perm_inv[j]);
        self.newton_factored = true;
        for i in 0..nx {
            self.t[i] = self.x[i] - record.x[j][i];
        }
        for c in 0..self.nu {
            let du = 0.5 * self.h * (u[c] - record.u[c]);
            if du != 0.0 {
                crate::la::axpy(&mut self.t, du, &record.fu[j].as_slice()[c * nx..(c + 1) * nx]);
            }
        }
        Self::solve_newton(&self.lu, &self.perm, &self.perm_inv, &mut self.mem, &mut self.t, 1);
        for i in 0..nx {
            self.xs[i] = record.m[j][i] + self.t[i];
        }
    }
}
