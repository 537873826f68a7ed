//! [`RomDynamics`]: the augmented modal model (29) as an [`ocp_transcription::Dynamics`], with
//! exact Jacobians, exact second derivatives and its constant linear part `W`.

use crate::error::{invalid, Result};
use modal_rom::ModalRom;
use nalgebra::DMatrix;
use ocp_transcription::{Dynamics, QuadraticTerms};

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
/// The Jacobian of the quadratic part is formed by [`QuadraticTerms`] (a precomputed map from
/// `q` into the column-major Jacobian, evaluated by an ELLPACK-style kernel instead of
/// entry-by-entry matrix indexing), and the integrator's Lawson stage gets `f − Wq` and
/// `∂f/∂q − W` directly ([`Dynamics::remainder_and_jacobians`]).
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
    /// Every `Γ` term as `f_a += v q_b q_c` (`Γ1`, then `Γ2` (two terms per entry), then
    /// `Γξ`, in entry order), with the Jacobian kernel.
    quad: Box<QuadraticTerms>,
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
        let gamma1 = conv(&rom.gamma1().entries);
        let gamma2 = conv(&rom.gamma2().entries);
        let (o2, ox) = (m, m + nq2);
        let mut terms = Vec::with_capacity(gamma1.len() + 2 * gamma2.len() + gamma_xi.len());
        for &(i, j, l, v) in &gamma1 {
            terms.push((i, j, l, -v));
        }
        for &(i, j, l, v) in &gamma2 {
            terms.push((i, o2 + j, o2 + l, -v));
            terms.push((o2 + j, i, o2 + l, v));
        }
        for &(i, j, l, v) in &gamma_xi {
            terms.push((ox + i, j, ox + l, v));
        }
        let quad = QuadraticTerms::new(m + nq2 + nxi, &terms)
            .map_err(|e| invalid("rom Γ tensors", e.to_string(), "must be finite, in range"))?;
        let out = Self { m, nq2, nxi, nu, sigma, b_u, omega, quad: Box::new(quad) };
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

    /// `fu = ∂f/∂u` (`B_u` in the `q1` rows).
    fn write_fu(&self, fu: &mut DMatrix<f64>) {
        fu.as_mut_slice().fill(0.0);
        for i in 0..self.m {
            for c in 0..self.nu {
                fu[(i, c)] = self.b_u[i * self.nu + c];
            }
        }
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
        // Γ terms (the same products in the same order as the entry lists: −v·a·b added is
        // v·a·b subtracted, bit for bit)
        self.quad.add_rhs(q, out);
    }

    fn jacobians(&self, q: &[f64], _u: &[f64], fx: &mut DMatrix<f64>, fu: &mut DMatrix<f64>) {
        let m = self.m;
        let o2 = self.m;
        fx.as_mut_slice().fill(0.0);
        for i in 0..m {
            for j in 0..m {
                fx[(i, j)] = self.sigma[i * m + j];
            }
        }
        for &(j, p, w) in &self.omega {
            fx[(j, o2 + p)] += w;
            fx[(o2 + p, j)] -= w;
        }
        self.quad.add_jacobian(q, fx.as_mut_slice());
        self.write_fu(fu);
    }

    fn remainder_and_jacobians(
        &self,
        q: &[f64],
        u: &[f64],
        g: &mut [f64],
        gx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
    ) -> bool {
        // gx = ∂(N(q)q)/∂q (the linear part W = [Σ, Ω; −Ω, 0] is not in it), and by Euler's
        // identity for the quadratic part g = f − Wq = ½ gx q + B_u u
        let (n, m, nu) = (self.nx(), self.m, self.nu);
        let j = gx.as_mut_slice();
        j.fill(0.0);
        self.quad.add_jacobian(q, j);
        g.fill(0.0);
        for (c, col) in j.chunks_exact(n).enumerate() {
            let qc = 0.5 * q[c];
            for (gi, jv) in g.iter_mut().zip(col) {
                *gi += jv * qc;
            }
        }
        for i in 0..m {
            let brow = &self.b_u[i * nu..(i + 1) * nu];
            for c in 0..nu {
                g[i] += brow[c] * u[c];
            }
        }
        self.write_fu(fu);
        true
    }

    fn has_second_order(&self) -> bool {
        true
    }

    fn weighted_hessian(&self, _q: &[f64], _u: &[f64], w: &[f64], out: &mut DMatrix<f64>) {
        // Every nonlinear term is a bilinear product c·x_a·x_b in row i: it adds w_i c to
        // entries (a, b) and (b, a) (twice on the diagonal when a = b, as ∂²(x²) = 2).
        out.fill(0.0);
        let ld = out.nrows();
        self.quad.add_weighted_hessian(w, out.as_mut_slice(), ld);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Scenario, Setup};

    /// The Lawson stage evaluation (`f − Wq`, `∂f/∂q − W` by the Jacobian kernel and Euler's
    /// identity) against `rhs`, `jacobians` and `linear_part` at random states of the 3D and
    /// 2D ROMs (coarse meshes). Tolerance: sums of ≤ ~100 terms of size ≤ |Γ|·|q| ≈ 10², so
    /// round-off ≤ 1e-11 relative to the largest entry; a missing or doubled term is O(1).
    #[test]
    fn remainder_and_jacobians_match_rhs_and_jacobians_minus_w() {
        use intrinsic_beam::samples::random::random_vec;
        for scenario in [Scenario::paper_3d(10).unwrap(), Scenario::paper_2d(10).unwrap()] {
            let setup = Setup::new(&scenario).unwrap();
            let d = RomDynamics::new(&setup.rom).unwrap();
            let (n, nu) = (d.nx(), d.nu());
            let w = d.linear_part().unwrap();
            let mut rng = intrinsic_beam::samples::random::seeded(17);
            for _ in 0..8 {
                let q: Vec<f64> = random_vec(&mut rng, n).iter().map(|v| 2.0 * v).collect();
                let u: Vec<f64> = random_vec(&mut rng, nu).iter().map(|v| 5.0 * v).collect();
                let (mut f, mut g) = (vec![0.0; n], vec![f64::NAN; n]);
                let (mut fx, mut fu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, nu));
                let (mut gx, mut gu) =
                    (DMatrix::from_element(n, n, f64::NAN), DMatrix::from_element(n, nu, 1.0));
                d.rhs(&q, &u, &mut f);
                d.jacobians(&q, &u, &mut fx, &mut fu);
                assert!(d.remainder_and_jacobians(&q, &u, &mut g, &mut gx, &mut gu));
                let wq = &w * nalgebra::DVector::from_column_slice(&q);
                let scale = 1.0 + fx.amax() + f.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
                let dev_g = (0..n).map(|i| (g[i] - (f[i] - wq[i])).abs()).fold(0.0, f64::max);
                assert!(dev_g < 1e-11 * scale, "g: {dev_g:.2e} (scale {scale:.1e})");
                let dev_j = (&gx - (&fx - &w)).amax();
                assert!(dev_j < 1e-11 * scale, "gx: {dev_j:.2e}");
                assert_eq!(gu, fu);
            }
        }
    }
}
