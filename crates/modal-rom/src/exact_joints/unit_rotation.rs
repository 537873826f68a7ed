//! The joint rows read the joint quaternions through their unit rotations (theory.md §10.3):
//! `A_j = A_j(ξ̂_j)`, `ξ̂_j = ξ_j / |ξ_j|`. With `x̂` the state with every joint quaternion
//! scaled to unit length and `f̂ = f(x̂)` the evaluation there,
//!
//! ```text
//!   f(x)  = D f̂,                     D = diag(1 on p, p2, ξ_root; |ξ_j| on ξ_j's rows)
//!   ∂f/∂x = D (∂f̂/∂x̂) N + Σ_j E_j f̂_j ξ̂_jᵀ,   N = blockdiag(I; Π_j / |ξ_j|),  Π_j = I − ξ̂_j ξ̂_jᵀ
//! ```
//!
//! (`E_j` places joint `j`'s four rows and columns): the reduced rates depend on `ξ_j` only
//! through `ξ̂_j`, and `ξ̇_j` is linear in `ξ_j` at fixed rates. The evaluations below
//! ([`super::eval`], [`super::planar`]) run at `x̂`; this module maps their results to `x`.

use crate::error::{invalid, Result};
use crate::exact_joints::eval::{with_buffers, with_workspace};
use crate::exact_joints::model::ExactJointsRom;
use std::cell::RefCell;

/// A state with unit joint quaternions and the joint quaternions' norms.
#[derive(Debug, Default)]
struct UnitState {
    x: Vec<f64>,
    norm: Vec<f64>,
}

/// A shorter borrow of the optional Jacobian buffers.
fn reborrow<'a>(
    j: &'a mut Option<(&mut [f64], &mut [f64])>,
) -> Option<(&'a mut [f64], &'a mut [f64])> {
    j.as_mut().map(|(a, b)| (&mut **a, &mut **b))
}

thread_local! {
    static UNIT: RefCell<UnitState> = RefCell::new(UnitState::default());
}

impl ExactJointsRom {
    /// `x` with every joint quaternion scaled to unit length into `xh`, the norms into `norm`.
    pub(crate) fn unit_state(
        &self,
        x: &[f64],
        xh: &mut Vec<f64>,
        norm: &mut Vec<f64>,
    ) -> Result<()> {
        xh.clear();
        xh.extend_from_slice(x);
        norm.clear();
        for j in 0..self.n_joints() {
            let o = self.joint_offset(j);
            let s = xh[o..o + 4].iter().map(|v| v * v).sum::<f64>().sqrt();
            if s <= 0.0 || !s.is_finite() {
                return Err(invalid(
                    format!("joint quaternion {j} of the state"),
                    format!("{:?}", &x[o..o + 4]),
                    "a rotation quaternion must be non-zero",
                ));
            }
            if s != 1.0 {
                xh[o..o + 4].iter_mut().for_each(|v| *v /= s);
            }
            norm.push(s);
        }
        Ok(())
    }

    /// Right-hand side into `f` and, with `jac`, the exact Jacobians at `x` (module docs), by the
    /// planar evaluation where it applies and `planar` allows it, else the general one; the state
    /// and input are checked by the caller.
    pub(crate) fn evaluate(
        &self,
        x: &[f64],
        u: &[f64],
        f: &mut [f64],
        mut jac: Option<(&mut [f64], &mut [f64])>,
        planar: bool,
    ) -> Result<()> {
        with_buffers(
            &UNIT,
            |_| true,
            UnitState::default,
            |cell| {
                let UnitState { x: xh, norm } = cell;
                self.unit_state(x, xh, norm)?;
                let planar_done =
                    if planar { self.planar_eval(xh, u, f, reborrow(&mut jac)) } else { None };
                // the planar evaluation's quaternion columns are `∂f̂/∂x̂ Π` already
                let projected = match planar_done {
                    Some(done) => {
                        done?;
                        true
                    }
                    None => {
                        with_workspace(self, |ws| {
                            self.eval_into(ws, xh, u, f, reborrow(&mut jac))
                        })?;
                        false
                    }
                };
                if let Some((jx, ju)) = jac {
                    self.unit_jacobian(xh, norm, f, jx, ju, projected);
                }
                for (j, &s) in norm.iter().enumerate() {
                    if s != 1.0 {
                        let o = self.joint_offset(j);
                        f[o..o + 4].iter_mut().for_each(|v| *v *= s);
                    }
                }
                Ok(())
            },
        )
    }

    /// `∂f̂/∂x̂` (in `jx`, `ju`) to `∂f/∂x`, `∂f/∂u` (module docs); `f` holds `f̂`, `projected`:
    /// the quaternion columns are `∂f̂/∂x̂ Π` already.
    fn unit_jacobian(
        &self,
        xh: &[f64],
        norm: &[f64],
        f: &[f64],
        jx: &mut [f64],
        ju: &mut [f64],
        projected: bool,
    ) {
        let ns = self.n_state();
        for (j, &s) in norm.iter().enumerate() {
            let o = self.joint_offset(j);
            let xi = &xh[o..o + 4];
            if projected && s == 1.0 {
                continue;
            }
            let (head, tail) = jx.split_at_mut((o + 1) * ns);
            let c0 = &mut head[o * ns..];
            let (c1, tail) = tail.split_at_mut(ns);
            let (c2, c3) = tail.split_at_mut(ns);
            let c3 = &mut c3[..ns];
            for i in 0..ns {
                let d = if projected {
                    0.0
                } else {
                    c0[i] * xi[0] + c1[i] * xi[1] + c2[i] * xi[2] + c3[i] * xi[3]
                };
                c0[i] = (c0[i] - d * xi[0]) / s;
                c1[i] = (c1[i] - d * xi[1]) / s;
                c2[i] = (c2[i] - d * xi[2]) / s;
                c3[i] = (c3[i] - d * xi[3]) / s;
            }
        }
        let nu = self.n_inputs();
        for (j, &s) in norm.iter().enumerate() {
            let o = self.joint_offset(j);
            if s != 1.0 {
                for col in 0..ns {
                    jx[col * ns + o..col * ns + o + 4].iter_mut().for_each(|v| *v *= s);
                }
                for col in 0..nu {
                    ju[col * ns + o..col * ns + o + 4].iter_mut().for_each(|v| *v *= s);
                }
            }
            for c in 0..4 {
                for i in 0..4 {
                    jx[(o + c) * ns + o + i] += f[o + i] * xh[o + c];
                }
            }
        }
    }
}
