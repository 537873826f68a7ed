//! Stage evaluations and substeps of the explicit (RK4, Lawson RK4) and implicit midpoint
//! methods, forward sensitivities alongside.

use super::{Integrator, Pow, Warm, SIMPLIFIED_NEWTON_MAX_RATE};
use crate::dynamics::Dynamics;
use crate::error::{OcpError, Result};
use crate::la::{all_finite, axpy, lincomb, lincomb3, norm_inf};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor as lu_factor, solve as lu_solve};
use faer::{Conj, Par};
use nalgebra::DMatrix;

/// A simplified Newton step whose residual contraction is weaker than this is undone: the
/// full Newton step from its start replaces it (far from the solution, a poor step from a stale
/// factor can leave full Newton's basin; a contraction between
/// [`SIMPLIFIED_NEWTON_MAX_RATE`] and this only refreshes the factor at the new iterate).
const SIMPLIFIED_NEWTON_UNDO_RATE: f64 = 0.5;

impl Integrator {
    /// Evaluates stage `j` at `(xs, u)` (and its sensitivity at `sx`).
    pub(super) fn stage<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        j: usize,
        sens: bool,
        tape: Option<usize>,
    ) -> Result<()> {
        // the model's own `g = f − Lx`, `∂f/∂x − L` when `L` is its linear part (saves a
        // copy of `W` into the Jacobian and its subtraction at every stage)
        let remainder = sens
            && self.model_linear_part
            && model.remainder_and_jacobians(
                &self.xs,
                u,
                &mut self.k[j],
                &mut self.fx,
                &mut self.fu,
            );
        // a trial without sensitivities: the model's own `g = f − Lx` when it has one
        let remainder = remainder
            || (!sens && self.model_linear_part && model.remainder(&self.xs, u, &mut self.k[j]));
        if sens {
            self.evaluations.jacobians += 1;
        } else {
            self.evaluations.rhs += 1;
        }
        if !remainder {
            if sens {
                model.rhs_and_jacobians(&self.xs, u, &mut self.k[j], &mut self.fx, &mut self.fu);
            } else {
                model.rhs(&self.xs, u, &mut self.k[j]);
            }
            if let Some(lw) = &self.lawson {
                lw.l_op.apply_vec(&mut self.k[j], &self.xs, -1.0, true);
            }
        }
        if !all_finite(&self.k[j]) {
            return Err(OcpError::NonFiniteDynamics { stage: "rhs" });
        }
        // stage 1 reads the substep's `S` in place (no copy into `sx`)
        let sx = if j == 0 { &self.s } else { &self.sx };
        if let Some(base) = tape {
            self.tape_x[base + j].copy_from_slice(&self.xs);
            self.tape_s[base + j].copy_from(sx);
        }
        if sens {
            if !remainder {
                if let Some(lw) = &self.lawson {
                    self.fx -= &lw.l;
                }
            }
            // a NaN/∞ in the Jacobians propagates into the sensitivities, checked once per interval
            crate::la::mul_right_t(&mut self.ks[j], sx, &self.fx, &mut self.rows);
            for c in 0..self.nu {
                for i in 0..self.nx {
                    self.ks[j][(self.nx + c, i)] += self.fu[(i, c)];
                }
            }
        }
        Ok(())
    }

    pub(super) fn explicit_substep<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        sens: bool,
        tape: Option<usize>,
    ) -> Result<()> {
        let h = self.h;
        let sens = sens || tape.is_some();
        // stage 1: X1 = x (its sensitivity is `S` itself, read in place by `stage`)
        self.xs.copy_from_slice(&self.x);
        self.stage(model, u, 0, sens, tape)?;
        // E x, E k1 (and E S, E K1) serve stages 2 to 4 and the update, so that E² is never
        // applied: 4 propagator products per substep instead of 6
        Self::pow_vec(&self.lawson, Pow::E1, &mut self.ex, &self.x, 1.0, false);
        Self::pow_vec(&self.lawson, Pow::E1, &mut self.ek1, &self.k[0], 1.0, false);
        if sens {
            Self::pow_mat(&self.lawson, Pow::E1, &mut self.es, &self.s, 1.0, false);
            Self::pow_mat(&self.lawson, Pow::E1, &mut self.eks, &self.ks[0], 1.0, false);
        }
        // stage 2: X2 = E (x + h/2 k1) = Ex + h/2 Ek1
        lincomb(&mut self.xs, &self.ex, 0.5 * h, &self.ek1);
        if sens {
            lincomb(self.sx.as_mut_slice(), self.es.as_slice(), 0.5 * h, self.eks.as_slice());
        }
        self.stage(model, u, 1, sens, tape)?;
        // stage 3: X3 = E x + h/2 k2
        lincomb(&mut self.xs, &self.ex, 0.5 * h, &self.k[1]);
        if sens {
            lincomb(self.sx.as_mut_slice(), self.es.as_slice(), 0.5 * h, self.ks[1].as_slice());
        }
        self.stage(model, u, 2, sens, tape)?;
        // stage 4: X4 = E² x + h E k3 = E (Ex + h k3)
        lincomb(&mut self.t, &self.ex, h, &self.k[2]);
        Self::pow_vec(&self.lawson, Pow::E1, &mut self.xs, &self.t, 1.0, false);
        if sens {
            lincomb(self.tm.as_mut_slice(), self.es.as_slice(), h, self.ks[2].as_slice());
            Self::pow_mat(&self.lawson, Pow::E1, &mut self.sx, &self.tm, 1.0, false);
        }
        self.stage(model, u, 3, sens, tape)?;
        // x⁺ = E²(x + h/6 k1) + h/3 E(k2 + k3) + h/6 k4
        //    = E (Ex + h/6 Ek1 + h/3 (k2 + k3)) + h/6 k4
        let (h6, h3) = (h / 6.0, h / 3.0);
        lincomb3(&mut self.t, &self.ex, h6, &self.ek1, h3, &self.k[1], &self.k[2]);
        Self::pow_vec(&self.lawson, Pow::E1, &mut self.x, &self.t, 1.0, false);
        axpy(&mut self.x, h6, &self.k[3]);
        if sens {
            lincomb3(
                self.tm.as_mut_slice(),
                self.es.as_slice(),
                h6,
                self.eks.as_slice(),
                h3,
                self.ks[1].as_slice(),
                self.ks[2].as_slice(),
            );
            Self::pow_mat(&self.lawson, Pow::E1, &mut self.s, &self.tm, 1.0, false);
            axpy(self.s.as_mut_slice(), h6, self.ks[3].as_slice());
        }
        Ok(())
    }

    /// Factorises `lu = I − h/2 fx` in place.
    pub(super) fn factor_newton(&mut self) -> Result<()> {
        self.evaluations.factorisations += 1;
        let nx = self.nx;
        self.newton_factored = false;
        self.lu.copy_from(&self.fx);
        self.lu *= -0.5 * self.h;
        for i in 0..nx {
            self.lu[(i, i)] += 1.0;
        }
        let (r, c) = self.lu.shape();
        let view = faer::MatMut::from_column_major_slice_mut(self.lu.as_mut_slice(), r, c);
        let _ = lu_factor::lu_in_place(
            view,
            &mut self.perm,
            &mut self.perm_inv,
            Par::Seq,
            MemStack::new(&mut self.mem),
            Default::default(),
        );
        for i in 0..nx {
            let d = self.lu[(i, i)];
            if d == 0.0 || !d.is_finite() {
                return Err(OcpError::Singular { what: "implicit midpoint Newton matrix" });
            }
        }
        self.newton_factored = true;
        Ok(())
    }

    /// Solves with the factorised Newton matrix, in place, for `rhs` (`nx × m`, column-major).
    pub(super) fn solve_newton(
        lu: &DMatrix<f64>,
        perm: &[usize],
        perm_inv: &[usize],
        mem: &mut MemBuffer,
        rhs: &mut [f64],
        m: usize,
    ) {
        let n = lu.nrows();
        let lu_ref = faer::MatRef::from_column_major_slice(lu.as_slice(), n, n);
        // SAFETY-free: the permutation arrays come from lu_in_place.
        let p = faer::perm::PermRef::new_checked(perm, perm_inv, n);
        lu_solve::solve_in_place_with_conj(
            lu_ref,
            lu_ref,
            p,
            Conj::No,
            faer::MatMut::from_column_major_slice_mut(rhs, n, m),
            Par::Seq,
            MemStack::new(mem),
        );
    }

    pub(super) fn midpoint_substep<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        sens: bool,
        j: usize,
        warm: &mut Warm<'_>,
    ) -> Result<()> {
        let h = self.h;
        let nx = self.nx;
        let first = j == 0;
        // initial guess. Simplified Newton: the previous substep's midpoint `m_{j−1}`, whose
        // residual for this substep, `m_{j−1} − x − h/2 f(m_{j−1})`, is known without an
        // evaluation (`xs` and its slope `k[0]` are left by the previous substep's converged
        // residual), so the first step is the previous factor's linearly implicit step
        // `m_{j−1} + M⁻¹ (x − x_{j−1})`, exact for linear dynamics; in the first substep the
        // start `x` itself (its residual `−h/2 f(x)` is the only evaluation; the first Newton
        // step from it is the linearly implicit Euler half step, stable for the stiff modes).
        // Full Newton: the explicit half step `m = x + h/2 f(x)` (one more evaluation). From a
        // record: its first-order predictor and Newton matrix (`warm_start`)
        let mut known_slope = false;
        // a midpoint converged in an earlier integration from the same data: its residual is
        // evaluated with the Jacobians (one evaluation when it passes)
        let mut reuse = false;
        if let Warm::Start(record) = warm {
            self.predict_midpoint(record, j, u);
        } else if let Warm::Record { record, reuse: true } = warm {
            self.xs.copy_from_slice(Self::path_midpoint(record, j));
            reuse = true;
        } else if !self.simplified_newton {
            self.xs.copy_from_slice(&self.x);
            self.evaluations.rhs += 1;
            model.rhs(&self.x, u, &mut self.k[0]);
            if !all_finite(&self.k[0]) {
                return Err(OcpError::NonFiniteDynamics { stage: "rhs" });
            }
            axpy(&mut self.xs, 0.5 * h, &self.k[0]);
        } else if first {
            self.xs.copy_from_slice(&self.x);
        } else {
            known_slope = true;
        }
        let mut converged = false;
        let mut residual = f64::INFINITY;
        // the residual of the previous iterate, and whether the correction from it used a
        // factor evaluated elsewhere (a simplified step)
        let mut previous = f64::INFINITY;
        let mut stale = false;
        let mut it = 0;
        // whether `fx`, `fu` hold the Jacobians at the current iterate, and the residual the
        // last contraction predicts for it
        let mut jacobians_here = false;
        let mut predicted = f64::INFINITY;
        while it <= self.newton_max_iterations {
            if !known_slope {
                // the Jacobians are evaluated with the residual (one model evaluation,
                // `rhs_and_jacobians`) and refresh the factor at the iterate after the first
                // step (`IntegratorSettings::refresh_after_first_step`), and, with
                // sensitivities, where the last contraction repeated passes the test (they
                // are needed at the converged midpoint; when the test fails they refresh)
                jacobians_here = sens && reuse && it == 0
                    || self.simplified_newton
                        && (self.refresh_after_first_step && it == 1
                            || sens
                                && predicted <= self.newton_tolerance * (1.0 + norm_inf(&self.xs)));
                if jacobians_here {
                    self.evaluations.jacobians += 1;
                    model.rhs_and_jacobians(
                        &self.xs,
                        u,
                        &mut self.k[0],
                        &mut self.fx,
                        &mut self.fu,
                    );
                } else {
                    self.evaluations.rhs += 1;
                    model.rhs(&self.xs, u, &mut self.k[0]);
                }
                if !all_finite(&self.k[0]) {
                    return Err(OcpError::NonFiniteDynamics { stage: "rhs" });
                }
            }
            known_slope = false;
            for i in 0..nx {
                self.t[i] = self.xs[i] - self.x[i] - 0.5 * h * self.k[0][i];
            }
            residual = norm_inf(&self.t);
            if residual <= self.newton_tolerance * (1.0 + norm_inf(&self.xs)) {
                converged = true;
                break;
            }
            if it == self.newton_max_iterations {
                break;
            }
            // full Newton: a Jacobian at every iterate. Simplified: the interval's last factor
            // while each step contracts the residual by SIMPLIFIED_NEWTON_MAX_RATE; a weaker
            // contraction refreshes the factor at the current iterate, and a simplified step
            // contracting by less than SIMPLIFIED_NEWTON_UNDO_RATE is undone and replaced by
            // the full Newton step from its start (far from the solution the iteration then
            // follows full Newton's path)
            let slow = residual > SIMPLIFIED_NEWTON_MAX_RATE * previous;
            predicted =
                if previous.is_finite() { residual * (residual / previous) } else { f64::INFINITY };
            let refresh = if !self.simplified_newton || !self.newton_factored {
                true
            } else if stale && residual > SIMPLIFIED_NEWTON_UNDO_RATE * previous {
                self.xs.copy_from_slice(&self.m_prev);
                self.t.copy_from_slice(&self.r_prev);
                residual = previous;
                jacobians_here = false;
                predicted = f64::INFINITY;
                true
            } else {
                slow || jacobians_here
            };
            if self.simplified_newton {
                self.m_prev.copy_from_slice(&self.xs);
                self.r_prev.copy_from_slice(&self.t);
                previous = residual;
                stale = !refresh;
            }
            if refresh {
                if !jacobians_here {
                    self.evaluations.jacobians += 1;
                    model.jacobians(&self.xs, u, &mut self.fx, &mut self.fu);
                }
                if !all_finite(self.fx.as_slice()) {
                    return Err(OcpError::NonFiniteDynamics { stage: "jacobian" });
                }
                self.factor_newton()?;
            }
            Self::solve_newton(&self.lu, &self.perm, &self.perm_inv, &mut self.mem, &mut self.t, 1);
            for i in 0..nx {
                self.xs[i] -= self.t[i];
            }
            if !all_finite(&self.xs) {
                return Err(OcpError::NonFiniteDynamics { stage: "state" });
            }
            it += 1;
        }
        if !converged {
            return Err(OcpError::NewtonFailed { iterations: it, residual });
        }
        if let Warm::Start(record) = warm {
            self.record_path_midpoint(record, j);
        }
        if sens {
            if !jacobians_here {
                self.evaluations.jacobians += 1;
                model.jacobians(&self.xs, u, &mut self.fx, &mut self.fu);
            }
            if !all_finite(self.fx.as_slice()) || !all_finite(self.fu.as_slice()) {
                return Err(OcpError::NonFiniteDynamics { stage: "jacobian" });
            }
            self.factor_newton()?;
            // (I − h/2 fx) ∂m/∂z = S + h/2 [0 | fu];  S⁺ = 2 ∂m/∂z − S
            let m = self.nx + self.nu;
            for j in 0..m {
                for i in 0..nx {
                    self.tcm[(i, j)] = self.s[(j, i)];
                }
            }
            axpy(&mut self.tcm.as_mut_slice()[nx * nx..], 0.5 * h, self.fu.as_slice());
            Self::solve_newton(
                &self.lu,
                &self.perm,
                &self.perm_inv,
                &mut self.mem,
                self.tcm.as_mut_slice(),
                m,
            );
            for j in 0..m {
                for i in 0..nx {
                    self.tm[(j, i)] = self.tcm[(i, j)];
                }
            }
            self.s *= -1.0;
            axpy(self.s.as_mut_slice(), 2.0, self.tm.as_slice());
            if let Warm::Record { record, .. } = warm {
                self.record_substep(record, j);
            }
        }
        for i in 0..nx {
            self.x[i] = 2.0 * self.xs[i] - self.x[i];
        }
        Ok(())
    }
}
