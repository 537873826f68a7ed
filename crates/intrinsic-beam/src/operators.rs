//! Pointwise operators of the intrinsic equations: `~`, `L1`, `L2`, `E` (eqs. 3–4), on
//! 6-component vectors and, in [`planar_ops`], on the in-plane 3-component restrictions.
//! The quaternion operators `U`, `Uω` and `T(ξ)` are in the `rotation` module.
//!
//! Conventions (theory.md §1, §6): `x1 = [v, ω]`, `x2 = [f, m]`, components ordered
//! `[1,2,3 | 1,2,3]`; quaternions `ξ = [ξ0, ξv]` (scalar first), `T(ξ)` maps local to global
//! components; `U(a) = ½ [[0, −aᵀ], [a, −ã]]` *with* the factor ½ of eq. (8), so that
//! `∂(U(ω)ξ)/∂ω = Uω(ξ) = ½ [[−ξvᵀ], [ξ0 I + ξ̃v]]` (the paper's eq. 24 drops the ½).

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// Cross-product matrix: `tilde(a) b = a × b`.
#[inline]
pub fn tilde(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// Splits a 6-vector into its linear and angular halves.
#[inline]
pub fn halves(x: &Vector6<f64>) -> (Vector3<f64>, Vector3<f64>) {
    (x.fixed_rows::<3>(0).into_owned(), x.fixed_rows::<3>(3).into_owned())
}

/// Joins two 3-vectors into a 6-vector `[a, b]`.
#[inline]
pub fn join(a: &Vector3<f64>, b: &Vector3<f64>) -> Vector6<f64> {
    Vector6::new(a.x, a.y, a.z, b.x, b.y, b.z)
}

/// `L1(x1) = [[ω̃, 0], [ṽ, ω̃]]` (eq. 4).
pub fn l1(x1: &Vector6<f64>) -> Matrix6<f64> {
    let (v, w) = halves(x1);
    let (wt, vt) = (tilde(&w), tilde(&v));
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&wt);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&vt);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&wt);
    m
}

/// `L2(x2) = [[0, f̃], [f̃, m̃]]` (eq. 4).
pub fn l2(x2: &Vector6<f64>) -> Matrix6<f64> {
    let (f, m) = halves(x2);
    let (ft, mt) = (tilde(&f), tilde(&m));
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&ft);
    out.fixed_view_mut::<3, 3>(3, 0).copy_from(&ft);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&mt);
    out
}

/// `L1(x1) p` without forming the matrix: `[ω×P, v×P + ω×H]` for `p = [P, H]`.
#[inline]
pub fn l1_times(x1: &Vector6<f64>, p: &Vector6<f64>) -> Vector6<f64> {
    let (v, w) = halves(x1);
    let (pp, h) = halves(p);
    join(&w.cross(&pp), &(v.cross(&pp) + w.cross(&h)))
}

/// `L2(x2) e` without forming the matrix: `[f×e_ω, f×e_v + m×e_ω]` for `e = [e_v, e_ω]`.
#[inline]
pub fn l2_times(x2: &Vector6<f64>, e: &Vector6<f64>) -> Vector6<f64> {
    let (f, m) = halves(x2);
    let (ev, ew) = halves(e);
    join(&f.cross(&ew), &(f.cross(&ev) + m.cross(&ew)))
}

/// Initial-curvature operator `E = [[κ̃0, 0], [ẽ1, κ̃0]]` (eq. 3).
pub fn e_matrix(kappa0: &Vector3<f64>) -> Matrix6<f64> {
    let kt = tilde(kappa0);
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&kt);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&tilde(&Vector3::x()));
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&kt);
    m
}

/// The operators of eqs. (3)–(4) on planar 3-vectors `x1 = (v1, v3, ω2)`,
/// `x2 = (f1, f3, m2)` (beam in the e1–e3 plane, `κ0 = κ e2`): the in-plane components of the
/// 6-component products, which have no out-of-plane part for in-plane arguments.
pub mod planar_ops {
    use nalgebra::Vector3;

    /// `L1(x1) p = [ω2 P3, −ω2 P1, v3 P1 − v1 P3]`.
    #[inline]
    pub fn l1_times(x1: &Vector3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(x1[2] * p[1], -x1[2] * p[0], x1[1] * p[0] - x1[0] * p[1])
    }

    /// `L2(x2) e = [−f3 e_ω, f1 e_ω, f3 e1 − f1 e3]`.
    #[inline]
    pub fn l2_times(x2: &Vector3<f64>, e: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(-x2[1] * e[2], x2[0] * e[2], x2[1] * e[0] - x2[0] * e[1])
    }

    /// `L1ᵀ(x1) y = [−y_f3 ω2 + y_m v3, y_f1 ω2 − y_m v1, 0]`.
    #[inline]
    pub fn l1t_times(x1: &Vector3<f64>, y: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(-y[1] * x1[2] + y[2] * x1[1], y[0] * x1[2] - y[2] * x1[0], 0.0)
    }

    /// `E x2 = [κ f3, −κ f1, −f3]`.
    #[inline]
    pub fn e_times(kappa: f64, x2: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(kappa * x2[1], -kappa * x2[0], -x2[1])
    }

    /// `Eᵀ x1 = [−κ v3, κ v1 − ω2, 0]`.
    #[inline]
    pub fn et_times(kappa: f64, x1: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(-kappa * x1[1], kappa * x1[0] - x1[2], 0.0)
    }
}

/// `E x2 = [κ0×f, e1×f + κ0×m]` (eq. 3) without forming the matrix.
#[inline]
pub fn e_times(kappa0: &Vector3<f64>, x2: &Vector6<f64>) -> Vector6<f64> {
    let (f, m) = halves(x2);
    join(&kappa0.cross(&f), &(Vector3::x().cross(&f) + kappa0.cross(&m)))
}

/// `Eᵀ x1 = [−κ0×v − e1×ω, −κ0×ω]` (eq. 3) without forming the matrix.
#[inline]
pub fn et_times(kappa0: &Vector3<f64>, x1: &Vector6<f64>) -> Vector6<f64> {
    let (v, w) = halves(x1);
    join(&(-kappa0.cross(&v) - Vector3::x().cross(&w)), &(-kappa0.cross(&w)))
}

/// `L1ᵀ(x1) y = [−ω×y_f − v×y_m, −ω×y_m]` without forming the matrix.
#[inline]
pub fn l1t_times(x1: &Vector6<f64>, y: &Vector6<f64>) -> Vector6<f64> {
    let (v, w) = halves(x1);
    let (yf, ym) = halves(y);
    join(&(yf.cross(&w) + ym.cross(&v)), &ym.cross(&w))
}

/// Matrix of `x1 ↦ L1ᵀ(x1) y`: `[[ỹ_m, ỹ_f], [0, ỹ_m]]` for `y = [y_f, y_m]`.
pub fn l1t_jacobian(y: &Vector6<f64>) -> Matrix6<f64> {
    let (yf, ym) = halves(y);
    let (tf, tm) = (tilde(&yf), tilde(&ym));
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&tm);
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&tf);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&tm);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v6(s: f64) -> Vector6<f64> {
        Vector6::from_fn(|i, _| ((i as f64 + 1.3) * s).sin())
    }

    #[test]
    fn l1_l2_products_match_matrices() {
        let (a, b) = (v6(0.7), v6(1.9));
        assert!((l1(&a) * b - l1_times(&a, &b)).norm() < 1e-14);
        assert!((l2(&a) * b - l2_times(&a, &b)).norm() < 1e-14);
    }
}
