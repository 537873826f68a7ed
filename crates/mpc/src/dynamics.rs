//! [`RomDynamics`]: the augmented modal model (29) as an [`ocp_transcription::Dynamics`], with
//! exact Jacobians, exact second derivatives and its constant linear part `W`.

use crate::error::{invalid, Result};
use modal_rom::ModalRom;
use nalgebra::DMatrix;
use ocp_transcription::Dynamics;

/// The augmented modal model (14)–(17), (26), (29) on `q_a = [q1, q2, qξ]`:
///
/// ```text
///   q̇1 = Σ q1 + Ω q2 − q1_l Γ1^l q1 − q2_l Γ2^l q2 + B_u u
///   q̇2 = −Ω q1 + q2_l (Γ2^l)ᵀ q1
///   q̇ξ = Aξ⁻¹ qξ_l Γξ^l q1
/// ```
///
/// Data are copied out of a [`ModalRom`] once (dense `Σ`, `B_u`; the sparse `Γ` entry lists),
/// so evaluation never allocates. The right-hand side is quadratic in `q` and linear in `u`:
/// the Jacobian is affine in `q` and exact, the second derivative is constant and exact.
#[derive(Clone, Debug)]
pub struct RomDynamics {
    m: usize,
    nq2: usize,
    nxi: usize,
    nu: usize,
    sigma: Vec<f64>,
    b_u: Vec<f64>,
    /// `(mode j, q2 slot p, Ω_j)`.
    omega: Vec<(usize, usize, f64)>,
    gamma1: Vec<(usize, usize, usize, f64)>,
    gamma2: Vec<(usize, usize, usize, f64)>,
    gamma_xi: Vec<(usize, usize, usize, f64)>,
}

impl RomDynamics {
    /// Copies the model data out of `rom` (augmented when it carries quaternion states).
    pub fn new(rom: &ModalRom) -> Result<Self> {
        let m = rom.n_modes();
        let nq2 = rom.n_q2();
        let nxi = rom.n_xi();
        let nu = rom.n_inputs();
        if nu == 0 {
            return Err(invalid("rom inputs", 0, "the controller model needs at least one input"));
        }
        let s = rom.sigma();
        let mut sigma = vec![0.0; m * m];
        for i in 0..m {
            for j in 0..m {
                sigma[i * m + j] = s[(i, j)];
            }
        }
        let b = rom.b_u();
        let mut b_u = vec![0.0; m * nu];
        for i in 0..m {
            for c in 0..nu {
                b_u[i * nu + c] = b[(i, c)];
            }
        }
        let omega =
            rom.q2_modes().iter().enumerate().map(|(p, &j)| (j, p, rom.omega()[j])).collect();
        let conv = |e: &[(u32, u32, u32, f64)]| -> Vec<(usize, usize, usize, f64)> {
            e.iter().map(|&(i, j, l, v)| (i as usize, j as usize, l as usize, v)).collect()
        };
        let gamma_xi = rom.quaternion().map_or(Vec::new(), |q| conv(&q.gamma_xi_scaled.entries));
        let out = Self {
            m,
            nq2,
            nxi,
            nu,
            sigma,
            b_u,
            omega,
            gamma1: conv(&rom.gamma1().entries),
            gamma2: conv(&rom.gamma2().entries),
            gamma_xi,
        };
        if !out.sigma.iter().chain(&out.b_u).all(|v| v.is_finite()) {
            return Err(invalid("rom", "non-finite Σ or B_u", "the model data must be finite"));
        }
        Ok(out)
    }

    /// Number of velocity modes `m`.
    pub fn n_modes(&self) -> usize {
        self.m
    }
    /// Number of `q2` coordinates.
    pub fn n_q2(&self) -> usize {
        self.nq2
    }
    /// Number of quaternion coordinates.
    pub fn n_xi(&self) -> usize {
        self.nxi
    }
    /// Offset of `q2` in the state.
    pub fn q2_offset(&self) -> usize {
        self.m
    }
    /// Offset of `qξ` in the state.
    pub fn xi_offset(&self) -> usize {
        self.m + self.nq2
    }
}

impl Dynamics for RomDynamics {
    fn nx(&self) -> usize {
        self.m + self.nq2 + self.nxi
    }

    fn nu(&self) -> usize {
        self.nu
    }

    fn rhs(&self, q: &[f64], u: &[f64], out: &mut [f64]) {
        let (m, nu) = (self.m, self.nu);
        let o2 = self.m;
        let ox = o2 + self.nq2;
        out.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..m {
            let mut acc = 0.0;
            let row = &self.sigma[i * m..(i + 1) * m];
            for j in 0..m {
                acc += row[j] * q[j];
            }
            let brow = &self.b_u[i * nu..(i + 1) * nu];
            for c in 0..nu {
                acc += brow[c] * u[c];
            }
            out[i] = acc;
        }
        for &(j, p, w) in &self.omega {
            out[j] += w * q[o2 + p];
            out[o2 + p] = -w * q[j];
        }
        for &(i, j, l, v) in &self.gamma1 {
            out[i] -= v * q[j] * q[l];
        }
        for &(i, j, l, v) in &self.gamma2 {
            out[i] -= v * q[o2 + j] * q[o2 + l];
            out[o2 + j] += v * q[i] * q[o2 + l];
        }
        for &(i, j, l, v) in &self.gamma_xi {
            out[ox + i] += v * q[j] * q[ox + l];
        }
    }

    fn jacobians(&self, q: &[f64], _u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        let (m, nu) = (self.m, self.nu);
        let o2 = self.m;
        let ox = o2 + self.nq2;
        fx.fill(0.0);
        fu.fill(0.0);
        for i in 0..m {
            for j in 0..m {
                fx[(i, j)] = self.sigma[i * m + j];
            }
            for c in 0..nu {
                fu[(i, c)] = self.b_u[i * nu + c];
            }
        }
        for &(j, p, w) in &self.omega {
            fx[(j, o2 + p)] += w;
            fx[(o2 + p, j)] -= w;
        }
        for &(i, j, l, v) in &self.gamma1 {
            fx[(i, j)] -= v * q[l];
            fx[(i, l)] -= v * q[j];
        }
        for &(i, j, l, v) in &self.gamma2 {
            fx[(i, o2 + j)] -= v * q[o2 + l];
            fx[(i, o2 + l)] -= v * q[o2 + j];
            fx[(o2 + j, i)] += v * q[o2 + l];
            fx[(o2 + j, o2 + l)] += v * q[i];
        }
        for &(i, j, l, v) in &self.gamma_xi {
            fx[(ox + i, j)] += v * q[ox + l];
            fx[(ox + i, ox + l)] += v * q[j];
        }
    }

    fn has_second_order(&self) -> bool {
        true
    }

    fn weighted_hessian(&self, _q: &[f64], _u: &[f64], w: &[f64], out: &mut DMatrix<f64>) {
        // Every nonlinear term is a bilinear product c·x_a·x_b in row i: it adds w_i c to
        // entries (a, b) and (b, a) (twice on the diagonal when a = b, as ∂²(x²) = 2).
        let o2 = self.m;
        let ox = o2 + self.nq2;
        out.fill(0.0);
        let mut add = |a: usize, b: usize, c: f64| {
            out[(a, b)] += c;
            out[(b, a)] += c;
        };
        for &(i, j, l, v) in &self.gamma1 {
            add(j, l, -w[i] * v);
        }
        for &(i, j, l, v) in &self.gamma2 {
            add(o2 + j, o2 + l, -w[i] * v);
            add(i, o2 + l, w[o2 + j] * v);
        }
        for &(i, j, l, v) in &self.gamma_xi {
            add(j, ox + l, w[ox + i] * v);
        }
    }

    fn linear_part(&self) -> Option<DMatrix<f64>> {
        let n = self.nx();
        let m = self.m;
        let mut l = DMatrix::zeros(n, n);
        for i in 0..m {
            for j in 0..m {
                l[(i, j)] = self.sigma[i * m + j];
            }
        }
        for &(j, p, w) in &self.omega {
            l[(j, m + p)] += w;
            l[(m + p, j)] -= w;
        }
        Some(l)
    }
}
