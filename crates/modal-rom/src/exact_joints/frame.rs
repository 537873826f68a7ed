//! The null-space basis `Z(ξ)` of the current compatibility rows and its derivatives
//! (theory §10.4).
//!
//! With `A = A(ξ)` (`r × na`, full row rank), `G = (AAᵀ)⁻¹`, `P = I − AᵀGA` and a fixed
//! orthonormal `Z0` (`na × m`) with `A(ξ̄) Z0 = 0`:
//!
//! ```text
//!   C0 = A Z0,   S = Z0ᵀ P Z0 = I − C0ᵀ G C0 = L Lᵀ,   Z̃ = Z0 L⁻ᵀ,   Z = P Z̃,
//!   B = A Z̃,   W = G B.
//! ```
//!
//! `ZᵀZ = I`, `AZ = 0`, and `Z = Z0` wherever `A Z0 = 0`. Along a change `Ȧ` of the rows, with
//! `V = ȦZ` and `Φ(X)` the lower triangle of `X` with half its diagonal:
//!
//! ```text
//!   X = −(WᵀV + VᵀW),  Λ = Φ(X),  Ż = −AᵀG V − P Ȧᵀ W − Z Λᵀ,  Z̃̇ = −Z̃ Λᵀ,
//!   K(Ȧ) = ZᵀŻ = −VᵀW − Λᵀ          (skew: K + Kᵀ = −(VᵀW + WᵀV) − X = 0).
//! ```
//!
//! At the reference rows (`A Z0 = 0`) `B = W = 0`, so `K = 0` for every `Ȧ`.

use crate::error::{ModalError, Result};
use faer::Mat;

/// `Z(ξ)` and the factors its derivatives need.
#[derive(Clone, Debug)]
pub(crate) struct NullFrame {
    pub a: Mat<f64>,
    pub g: Mat<f64>,
    pub z: Mat<f64>,
    pub zt: Mat<f64>,
    pub b: Mat<f64>,
    pub w: Mat<f64>,
}

/// Lower Cholesky factor of a symmetric positive definite matrix, `None` when a pivot is
/// not above `tol`.
pub(crate) fn cholesky(s: &Mat<f64>, tol: f64) -> Option<Mat<f64>> {
    let n = s.nrows();
    let mut l = Mat::<f64>::zeros(n, n);
    for j in 0..n {
        let mut d = s[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        if d.is_nan() || d <= tol {
            return None;
        }
        let dj = d.sqrt();
        l[(j, j)] = dj;
        for i in j + 1..n {
            let mut v = s[(i, j)];
            for k in 0..j {
                v -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = v / dj;
        }
    }
    Some(l)
}

/// Inverse of a lower-triangular matrix.
fn lower_inverse(l: &Mat<f64>) -> Mat<f64> {
    let n = l.nrows();
    let mut inv = Mat::<f64>::zeros(n, n);
    for c in 0..n {
        inv[(c, c)] = 1.0 / l[(c, c)];
        for i in c + 1..n {
            let mut v = 0.0;
            for k in c..i {
                v -= l[(i, k)] * inv[(k, c)];
            }
            inv[(i, c)] = v / l[(i, i)];
        }
    }
    inv
}

/// Inverse of a symmetric positive definite matrix by Cholesky.
pub(crate) fn spd_inverse(s: &Mat<f64>, what: &str) -> Result<Mat<f64>> {
    let scale = (0..s.nrows()).fold(0.0f64, |m, i| m.max(s[(i, i)]));
    let l = cholesky(s, 1e-14 * scale).ok_or_else(|| ModalError::Numerical {
        stage: what.to_string(),
        reason: "matrix is not positive definite (dependent rows)".into(),
    })?;
    let li = lower_inverse(&l);
    Ok(li.transpose() * &li)
}

/// `Φ(X)ᵀ`: the upper triangle of `X` with half its diagonal.
pub(crate) fn phi_t(x: &Mat<f64>) -> Mat<f64> {
    let n = x.nrows();
    Mat::from_fn(n, n, |i, j| match i.cmp(&j) {
        std::cmp::Ordering::Less => x[(j, i)],
        std::cmp::Ordering::Equal => 0.5 * x[(i, i)],
        std::cmp::Ordering::Greater => 0.0,
    })
}

impl NullFrame {
    /// The frame for rows `a`; `z0` orthonormal with `A(ξ̄) z0 = 0`. Errors when `Z0` has
    /// (nearly) left the null space (`S` not positive definite): the joint rotation is
    /// outside the range the fields can represent.
    pub fn new(a: Mat<f64>, z0: &Mat<f64>) -> Result<Self> {
        let m = z0.ncols();
        if a.nrows() == 0 {
            let g = Mat::zeros(0, 0);
            return Ok(NullFrame {
                b: Mat::zeros(0, m),
                w: Mat::zeros(0, m),
                z: z0.clone(),
                zt: z0.clone(),
                a,
                g,
            });
        }
        let g = spd_inverse(&(&a * a.transpose()), "Gram matrix of the joint rows AAᵀ")?;
        let c0 = &a * z0;
        let gc0 = &g * &c0;
        let cgc = c0.transpose() * &gc0;
        let s = Mat::from_fn(m, m, |i, j| {
            let delta = if i == j { 1.0 } else { 0.0 };
            delta - 0.5 * (cgc[(i, j)] + cgc[(j, i)])
        });
        let l = cholesky(&s, 1e-10).ok_or_else(|| ModalError::Numerical {
            stage: "null-space basis Z(ξ)".into(),
            reason: "the joint rotation is outside the range of the fields (ZᵀP Z0 singular)"
                .into(),
        })?;
        let lit = lower_inverse(&l).transpose().to_owned();
        let zt = z0 * &lit;
        let y = z0 - a.transpose() * &gc0;
        let z = &y * &lit;
        let b = &c0 * &lit;
        let w = &g * &b;
        Ok(NullFrame { a, g, z, zt, b, w })
    }

    /// `P v = v − AᵀG A v`.
    pub fn project(&self, v: &Mat<f64>) -> Mat<f64> {
        if self.a.nrows() == 0 {
            return v.clone();
        }
        v - self.a.transpose() * (&self.g * (&self.a * v))
    }

    /// `K(Ȧ) = ZᵀŻ` (skew, `m × m`).
    pub fn k_of(&self, adot: &Mat<f64>) -> Mat<f64> {
        let v = adot * &self.z;
        self.k_from_v(&v)
    }

    fn k_from_v(&self, v: &Mat<f64>) -> Mat<f64> {
        let vtw = v.transpose() * &self.w;
        let x = Mat::from_fn(vtw.nrows(), vtw.ncols(), |i, j| -(vtw[(i, j)] + vtw[(j, i)]));
        Mat::from_fn(vtw.nrows(), vtw.ncols(), |i, j| -vtw[(i, j)]) - phi_t(&x)
    }

    /// `(Ż, Λ)` along `Ȧ`.
    pub fn z_dot(&self, adot: &Mat<f64>) -> (Mat<f64>, Mat<f64>) {
        let v = adot * &self.z;
        let vtw = v.transpose() * &self.w;
        let x = Mat::from_fn(vtw.nrows(), vtw.ncols(), |i, j| -(vtw[(i, j)] + vtw[(j, i)]));
        let lam_t = phi_t(&x);
        let m1 = if self.a.nrows() == 0 {
            Mat::zeros(self.z.nrows(), self.z.ncols())
        } else {
            -(self.a.transpose() * (&self.g * &v)) - self.project(&(adot.transpose() * &self.w))
        };
        (m1 - &self.z * &lam_t, lam_t)
    }

    /// `∂K(Ȧ)` along a change `ac` of the rows (with `Ż_c = zc`, `Λ_cᵀ = lam_t_c`) and the
    /// change `adot_c` of `Ȧ` itself.
    pub fn k_derivative(
        &self,
        adot: &Mat<f64>,
        adot_c: &Mat<f64>,
        ac: &Mat<f64>,
        zc: &Mat<f64>,
        lam_t_c: &Mat<f64>,
    ) -> Mat<f64> {
        let v = adot * &self.z;
        let dv = adot_c * &self.z + adot * zc;
        let ztc = -(&self.zt * lam_t_c);
        let dg = -(&self.g * (ac * self.a.transpose() + &self.a * ac.transpose()) * &self.g);
        let db = ac * &self.zt + &self.a * &ztc;
        let dw = &dg * &self.b + &self.g * &db;
        let t1 = dv.transpose() * &self.w + v.transpose() * &dw;
        let x = Mat::from_fn(t1.nrows(), t1.ncols(), |i, j| t1[(i, j)] + t1[(j, i)]);
        -t1 + phi_t(&x)
    }
}
