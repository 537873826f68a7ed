//! The backward (adjoint) sweep of the exact second derivative `∇²(λᵀΦ)` over the taped
//! forward pass of the explicit methods.

use super::{Integrator, Pow};
use crate::dynamics::Dynamics;
use crate::error::{OcpError, Result};
use crate::la::{all_finite, axpy, gemm, gemv_t};
use nalgebra::DMatrix;

impl Integrator {
    /// Backward sweep over the tape: accumulates `Σ Ŝⱼᵀ (k̄ⱼ·∇²f) Ŝⱼ` into `out`.
    pub(super) fn backward<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        lambda: &[f64],
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        let h = self.h;
        let nx = self.nx;
        let nz = nx + self.nu;
        out.fill(0.0);
        self.lbar.copy_from_slice(lambda);
        for n in (0..self.substeps).rev() {
            let base = 4 * n;
            // k̄4 = h/6 λ̄
            for i in 0..nx {
                self.kbar[3][i] = h / 6.0 * self.lbar[i];
            }
            self.stage_adjoint(model, u, base, 3)?;
            // k̄3 = Eᵀ(h/3 λ̄ + h X̄4)
            for i in 0..nx {
                self.t[i] = h / 3.0 * self.lbar[i] + h * self.xbar[3][i];
            }
            Self::pow_t_vec(&self.lawson, Pow::E1, &mut self.kbar[2], &self.t, 1.0, false);
            self.stage_adjoint(model, u, base, 2)?;
            // k̄2 = h/3 Eᵀλ̄ + h/2 X̄3
            Self::pow_t_vec(&self.lawson, Pow::E1, &mut self.kbar[1], &self.lbar, h / 3.0, false);
            let (kb, xb) = (&mut self.kbar[1], &self.xbar[2]);
            axpy(kb, 0.5 * h, xb);
            self.stage_adjoint(model, u, base, 1)?;
            // k̄1 = h/6 E²ᵀ λ̄ + h/2 Eᵀ X̄2
            Self::pow_t_vec(&self.lawson, Pow::E2, &mut self.kbar[0], &self.lbar, h / 6.0, false);
            Self::pow_t_vec(&self.lawson, Pow::E1, &mut self.kbar[0], &self.xbar[1], 0.5 * h, true);
            self.stage_adjoint(model, u, base, 0)?;
            // λ̄ ← E²ᵀλ̄ + X̄1 + Eᵀ(X̄2 + X̄3) + E²ᵀ X̄4
            for i in 0..nx {
                self.t[i] = self.lbar[i] + self.xbar[3][i];
            }
            Self::pow_t_vec(&self.lawson, Pow::E2, &mut self.lbar, &self.t, 1.0, false);
            axpy(&mut self.lbar, 1.0, &self.xbar[0]);
            for i in 0..nx {
                self.t[i] = self.xbar[1][i] + self.xbar[2][i];
            }
            Self::pow_t_vec(&self.lawson, Pow::E1, &mut self.lbar, &self.t, 1.0, true);
            // Hessian contributions of the four stages of this substep
            for j in 0..4 {
                self.evaluations.hessians += 1;
                model.weighted_hessian(&self.tape_x[base + j], u, &self.kbar[j], &mut self.whess);
                if !all_finite(self.whess.as_slice()) {
                    return Err(OcpError::NonFiniteDynamics { stage: "hessian" });
                }
                self.shat.fill(0.0);
                for c in 0..nz {
                    for r in 0..nx {
                        self.shat[(r, c)] = self.tape_s[base + j][(c, r)];
                    }
                }
                for i in nx..nz {
                    self.shat[(i, i)] = 1.0;
                }
                gemm(&mut self.zz, &self.whess, &self.shat, 1.0, false);
                crate::la::gemm_tn(out, &self.shat, &self.zz, 1.0, true);
            }
        }
        // symmetrise against round-off
        for i in 0..nz {
            for j in 0..i {
                let v = 0.5 * (out[(i, j)] + out[(j, i)]);
                out[(i, j)] = v;
                out[(j, i)] = v;
            }
        }
        Ok(())
    }

    /// `X̄ⱼ = (∂g/∂x)ᵀ(Xⱼ) k̄ⱼ`.
    fn stage_adjoint<D: Dynamics + ?Sized>(
        &mut self,
        model: &D,
        u: &[f64],
        base: usize,
        j: usize,
    ) -> Result<()> {
        self.evaluations.jacobians += 1;
        model.jacobians(&self.tape_x[base + j], u, &mut self.fx, &mut self.fu);
        if let Some(lw) = &self.lawson {
            self.fx -= &lw.l;
        }
        if !all_finite(self.fx.as_slice()) {
            return Err(OcpError::NonFiniteDynamics { stage: "jacobian" });
        }
        gemv_t(&mut self.xbar[j], &self.fx, &self.kbar[j], 1.0, false);
        Ok(())
    }
}
