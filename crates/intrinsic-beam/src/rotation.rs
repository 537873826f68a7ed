//! Rotations as unit quaternions `ξ = [ξ0, ξv]` (scalar first): the quaternion rate operators
//! `U`, `Uω` (eqs. 7–8, 24), the rotation matrix `T(ξ)` (eq. 9) mapping local to global
//! components, the exact step `ξ⁺ = exp(dt U(ω)) ξ` (theory.md §2), and the quaternion algebra
//! joints and placements use (axis–angle, Hamilton product, conjugate, rotation angle).
//!
//! `U(a) = ½ [[0, −aᵀ], [a, −ã]]` *with* the factor ½ of eq. (8), so that
//! `∂(U(ω)ξ)/∂ω = Uω(ξ) = ½ [[−ξvᵀ], [ξ0 I + ξ̃v]]` (the paper's eq. 24 drops the ½).

use nalgebra::{Matrix3, Matrix4, Matrix4x3, Quaternion, UnitQuaternion, Vector3, Vector4};

use crate::operators::tilde;

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

/// Unit quaternion (scalar first) of a rotation by `angle` about `axis` (any length; zero axis
/// with zero angle gives the identity).
pub fn axis_angle(axis: &Vector3<f64>, angle: f64) -> Vector4<f64> {
    let n = axis.norm();
    if n == 0.0 || angle == 0.0 {
        return Vector4::new(1.0, 0.0, 0.0, 0.0);
    }
    let a = axis / n * (0.5 * angle).sin();
    Vector4::new((0.5 * angle).cos(), a.x, a.y, a.z)
}

/// Hamilton product `p ⊗ q` of scalar-first quaternions: `T(p ⊗ q) = T(p) T(q)`.
pub fn quat_mul(p: &Vector4<f64>, q: &Vector4<f64>) -> Vector4<f64> {
    let (pw, pv) = (p[0], Vector3::new(p[1], p[2], p[3]));
    let (qw, qv) = (q[0], Vector3::new(q[1], q[2], q[3]));
    let w = pw * qw - pv.dot(&qv);
    let v = qv * pw + pv * qw + pv.cross(&qv);
    Vector4::new(w, v.x, v.y, v.z)
}

/// Conjugate (inverse of a unit quaternion).
pub fn quat_conj(q: &Vector4<f64>) -> Vector4<f64> {
    Vector4::new(q[0], -q[1], -q[2], -q[3])
}

/// Relative rotation angle (rad, in `[0, π]`) of a unit quaternion: `2 acos|ξ0|`.
pub fn rotation_angle(q: &Vector4<f64>) -> f64 {
    let uq = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
    uq.angle()
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// `T(p ⊗ q) = T(p) T(q)`, `T(conj q) = T(q)ᵀ`, and the axis–angle quaternion turns by its
    /// angle.
    #[test]
    fn quaternion_algebra_matches_rotation_matrices() {
        let p = axis_angle(&Vector3::new(0.3, -1.0, 0.2), 0.7);
        let q = axis_angle(&Vector3::new(-0.5, 0.1, 0.9), 1.3);
        let tpq = rotation(&quat_mul(&p, &q));
        assert!((tpq - rotation(&p) * rotation(&q)).amax() < 1e-15);
        assert!((rotation(&quat_conj(&q)) - rotation(&q).transpose()).amax() < 1e-15);
        assert!((rotation_angle(&q) - 1.3).abs() < 1e-15);
        assert_eq!(axis_angle(&Vector3::zeros(), 0.0), Vector4::new(1.0, 0.0, 0.0, 0.0));
    }
}
