//! Pointwise operators of the intrinsic equations: `~`, `L1`, `L2`, `E` (eqs. 3–4), the
//! quaternion operators `U`, `Uω` (eqs. 7–8, 24) and the rotation matrix `T(ξ)` (eq. 9).
//!
//! Conventions (theory.md §1, §6): `x1 = [v, ω]`, `x2 = [f, m]`, components ordered
//! `[1,2,3 | 1,2,3]`; quaternions `ξ = [ξ0, ξv]` (scalar first), `T(ξ)` maps local to global
//! components; `U(a) = ½ [[0, −aᵀ], [a, −ã]]` *with* the factor ½ of eq. (8), so that
//! `∂(U(ω)ξ)/∂ω = Uω(ξ) = ½ [[−ξvᵀ], [ξ0 I + ξ̃v]]` (the paper's eq. 24 drops the ½).

use nalgebra::{Matrix3, Matrix4, Matrix4x3, Matrix6, Vector3, Vector4, Vector6};

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

/// Quaternion rate operator `U(a) = ½ [[0, −aᵀ], [a, −ã]]` (eq. 8): `ξ̇ = U(ω) ξ` (eq. 7).
pub fn u_matrix(a: &Vector3<f64>) -> Matrix4<f64> {
    let h = 0.5;
    Matrix4::new(
        0.0,
        -h * a.x,
        -h * a.y,
        -h * a.z,
        h * a.x,
        0.0,
        h * a.z,
        -h * a.y,
        h * a.y,
        -h * a.z,
        0.0,
        h * a.x,
        h * a.z,
        h * a.y,
        -h * a.x,
        0.0,
    )
}

/// `Uω(ξ) = ∂(U(ω) ξ)/∂ω = ½ [[−ξvᵀ], [ξ0 I + ξ̃v]]` (eq. 24 with the ½ of eq. 8 kept).
///
/// Note the sign of `ξ̃v`: with `U` as in (8), `U(ω)ξ = ½[−ω·ξv, ξ0 ω − ω×ξv]` and
/// `−ω×ξv = ξv×ω`, so the lower block is `½(ξ0 I + ξ̃v)` acting on ω.
pub fn u_omega(xi: &Vector4<f64>) -> Matrix4x3<f64> {
    let xv = Vector3::new(xi[1], xi[2], xi[3]);
    let lower = Matrix3::identity() * xi[0] + tilde(&xv);
    let mut m = Matrix4x3::zeros();
    m.fixed_view_mut::<1, 3>(0, 0).copy_from(&(-xv.transpose()));
    m.fixed_view_mut::<3, 3>(1, 0).copy_from(&lower);
    m * 0.5
}

/// Rotation matrix from local to global components, eq. (9):
/// `T(ξ) = (1 − 2|ξv|²) I + 2 ξv ξvᵀ + 2 ξ0 ξ̃v`.
pub fn rotation(xi: &Vector4<f64>) -> Matrix3<f64> {
    let xv = Vector3::new(xi[1], xi[2], xi[3]);
    Matrix3::identity() * (1.0 - 2.0 * xv.norm_squared())
        + xv * xv.transpose() * 2.0
        + tilde(&xv) * (2.0 * xi[0])
}

/// Exact quaternion update for a body rate `ω` held constant over `dt`:
/// `ξ⁺ = exp(dt U(ω)) ξ`. Keeps `|ξ|` exactly (up to round-off); theory.md §2.
pub fn quaternion_step(xi: &Vector4<f64>, omega: &Vector3<f64>, dt: f64) -> Vector4<f64> {
    // U(ω)² = −(|ω|/2)² I, so exp(dt U) = cos(θ) I + sin(θ)/|ω/2| U with θ = dt |ω| / 2.
    let half_norm = 0.5 * omega.norm();
    let theta = dt * half_norm;
    let sinc = if half_norm * dt.abs() > 1e-8 {
        theta.sin() / half_norm
    } else {
        // sin(θ)/(θ/dt) series: dt (1 − θ²/6)
        dt * (1.0 - theta * theta / 6.0)
    };
    xi * theta.cos() + u_matrix(omega) * xi * sinc
}

/// [`quaternion_step`] over `dt/2` and over `dt` at once, for the same rate `ω`: one sine
/// and cosine of the half angle, the full step by the double-angle formulas (equal to two
/// calls up to round-off).
pub fn quaternion_half_and_full_step(
    xi: &Vector4<f64>,
    omega: &Vector3<f64>,
    dt: f64,
) -> (Vector4<f64>, Vector4<f64>) {
    let half_norm = 0.5 * omega.norm();
    // θ = dt |ω|/2 for the full step; the half step has θ/2
    let quarter = 0.5 * dt * half_norm;
    let (s, c) = quarter.sin_cos();
    let (sin_full, cos_full) = (2.0 * s * c, (c - s) * (c + s));
    let (sinc_half, sinc_full) = if half_norm * dt.abs() > 1e-8 {
        (s / half_norm, sin_full / half_norm)
    } else {
        let theta = dt * half_norm;
        (0.5 * dt * (1.0 - theta * theta / 24.0), dt * (1.0 - theta * theta / 6.0))
    };
    let u_xi = u_matrix(omega) * xi;
    (xi * c + u_xi * sinc_half, xi * cos_full + u_xi * sinc_full)
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

    #[test]
    fn u_omega_is_derivative_of_u() {
        let xi = Vector4::new(0.3, -0.5, 0.7, 0.1);
        let w = Vector3::new(0.2, -1.1, 0.4);
        assert!((u_matrix(&w) * xi - u_omega(&xi) * w).norm() < 1e-15);
    }

    #[test]
    fn rotation_of_unit_quaternion_is_orthogonal() {
        let xi = Vector4::new(0.3, -0.5, 0.7, 0.1).normalize();
        let t = rotation(&xi);
        assert!((t.transpose() * t - Matrix3::identity()).norm() < 1e-14);
        assert!((t.determinant() - 1.0).abs() < 1e-14);
    }

    #[test]
    fn half_and_full_steps_match_two_quaternion_steps() {
        let xi = Vector4::new(0.3, -0.5, 0.7, 0.1).normalize();
        for (w, dt) in [(Vector3::new(0.2, -1.1, 0.4), 0.3), (Vector3::new(1e-9, 0.0, 2e-9), 1e-3)]
        {
            let (half, full) = quaternion_half_and_full_step(&xi, &w, dt);
            assert!((half - quaternion_step(&xi, &w, 0.5 * dt)).amax() < 1e-15);
            assert!((full - quaternion_step(&xi, &w, dt)).amax() < 1e-15);
        }
    }

    #[test]
    fn quaternion_step_matches_rotation_about_fixed_axis() {
        // ω = θ̇ e3 for time dt rotates by angle θ = ω dt about e3: ξ = [cos θ/2, 0, 0, sin θ/2].
        let xi0 = Vector4::new(1.0, 0.0, 0.0, 0.0);
        let xi = quaternion_step(&xi0, &Vector3::new(0.0, 0.0, 2.0), 0.3);
        let expect = Vector4::new((0.3f64).cos(), 0.0, 0.0, (0.3f64).sin());
        assert!((xi - expect).norm() < 1e-15);
        let t = rotation(&xi);
        assert!((t * Vector3::x() - Vector3::new(0.6f64.cos(), 0.6f64.sin(), 0.0)).norm() < 1e-15);
    }
}
