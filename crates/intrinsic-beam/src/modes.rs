//! Linear (undamped, at rest) modes of a single beam with its end conditions, by the
//! second-order reduction of theory.md §4, on dense faer matrices (small meshes).
//!
//! From `B Ẋ = A X` with the end conditions eliminated (prescribed-velocity components remove
//! their node unknown, node row and reaction; force components remove their end value),
//! `B1 Ẋ1 = D X2`, `B2 Ẋ2 = −Dᵀ X1`. Rigid element components (`B2` rows zero) give the
//! constraint `D_Rᵀ X1 = 0`, handled by a null-space basis `Z` (faer SVD); the flexible ones
//! give `K = D_F B2_F⁻¹ D_Fᵀ`. On `X1 = Z y`: `ω² ZᵀB1Z y = ZᵀKZ y`. Massless directions
//! (zero eigenvalues of `ZᵀB1Z`) are condensed statically (Schur complement of `K`), and the
//! remaining symmetric definite problem is solved with faer's self-adjoint eigensolver.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};

use crate::beam::Beam;
use crate::error::{BeamError, Result};
use crate::problem::{BeamProblem, End};

/// One linear mode: angular frequency and node-velocity shape `φ1` (length `k(N+1)`, node
/// layout of the beam vector), normalised `Σ w_n φ1ᵀ M φ1 = 1`.
#[derive(Clone, Debug)]
pub struct LinearMode {
    /// Angular frequency `ω ≥ 0`.
    pub omega: f64,
    /// Node velocities.
    pub phi1: Vec<f64>,
}

/// Families of a straight beam's modes, by where their kinetic energy lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// `v1` (extension).
    Axial,
    /// `ω1` (twist).
    Torsion,
    /// Bending about e2 (`v3`, `ω2`, deflection along e3).
    BendingE2,
    /// Bending about e3 (`v2`, `ω3`, deflection along e2).
    BendingE3,
}

/// Relative threshold for singular values / eigenvalues treated as zero (well above
/// round-off `1e-16 ×` matrix norm, far below the physical ratios of the sections used).
const RANK_TOLERANCE: f64 = 1e-10;

fn dense(list: &[(usize, usize, f64)], rows: &[usize], cols: &[usize], dim: usize) -> Mat<f64> {
    let mut row_pos = vec![usize::MAX; dim];
    let mut col_pos = vec![usize::MAX; dim];
    for (i, &r) in rows.iter().enumerate() {
        row_pos[r] = i;
    }
    for (j, &c) in cols.iter().enumerate() {
        col_pos[c] = j;
    }
    let mut m = Mat::zeros(rows.len(), cols.len());
    for &(r, c, v) in list {
        if r < dim && c < dim && row_pos[r] != usize::MAX && col_pos[c] != usize::MAX {
            m[(row_pos[r], col_pos[c])] += v;
        }
    }
    m
}

/// All linear modes of `problem` (end-condition *values* are ignored, their kinds used),
/// sorted by frequency. Rigid-body modes appear with `ω ≈ 0`.
pub fn linear_modes(problem: &BeamProblem) -> Result<Vec<LinearMode>> {
    let beam = &problem.beam;
    let k = beam.k();
    let n = beam.n_elements();
    let idx = beam.components().indices();
    let ops = beam.linear_operators();
    // node unknowns kept: all except prescribed-velocity end components
    let mut prescribed = vec![false; k * (n + 1)];
    for end in [End::Left, End::Right] {
        for a in 0..k {
            let u = problem.end_unknown(end, a);
            if u < k * (n + 1) {
                prescribed[u] = true;
            }
        }
    }
    let x1: Vec<usize> = (0..k * (n + 1)).filter(|&i| !prescribed[i]).collect();
    let (mut x2f, mut x2r) = (Vec::new(), Vec::new());
    for e in 0..n {
        for a in 0..k {
            let i = beam.x2_index(e, a);
            if beam.section().rigid[idx[a]] {
                x2r.push(i);
            } else {
                x2f.push(i);
            }
        }
    }
    let dim = ops.dim;
    let d_f = dense(&ops.a, &x1, &x2f, dim);
    let d_r = dense(&ops.a, &x1, &x2r, dim);
    let b1 = dense(&ops.b, &x1, &x1, dim);
    let b2 = dense(&ops.b, &x2f, &x2f, dim);
    // K = D_F B2⁻¹ D_Fᵀ (B2 block diagonal SPD on flexible components)
    let k_full = if x2f.is_empty() {
        Mat::zeros(x1.len(), x1.len())
    } else {
        let llt = b2
            .llt(Side::Lower)
            .map_err(|e| BeamError::LinearSolve { reason: format!("B2 Cholesky: {e:?}") })?;
        let sol = llt.solve(d_f.transpose().to_owned());
        &d_f * &sol
    };
    // Z = null(D_Rᵀ)
    let z = if x2r.is_empty() {
        Mat::<f64>::identity(x1.len(), x1.len())
    } else {
        null_space(&d_r.transpose().to_owned())?
    };
    let bz = z.transpose() * &b1 * &z;
    let kz = z.transpose() * &k_full * &z;
    let bz = symmetrize(&bz);
    let kz = symmetrize(&kz);
    // split Bz into massive and massless subspaces
    let evd = bz
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| BeamError::LinearSolve { reason: format!("eigen of B: {e:?}") })?;
    let bvals: Vec<f64> = (0..bz.nrows()).map(|i| evd.S()[i]).collect();
    let bmax = bvals.iter().cloned().fold(0.0, f64::max);
    let massive: Vec<usize> =
        (0..bvals.len()).filter(|&i| bvals[i] > RANK_TOLERANCE * bmax).collect();
    let massless: Vec<usize> =
        (0..bvals.len()).filter(|&i| bvals[i] <= RANK_TOLERANCE * bmax).collect();
    let q = evd.U();
    let q1 = Mat::from_fn(q.nrows(), massive.len(), |i, j| q[(i, massive[j])]);
    let q0 = Mat::from_fn(q.nrows(), massless.len(), |i, j| q[(i, massless[j])]);
    let k11 = q1.transpose() * &kz * &q1;
    let (k_eff, recover) = if massless.is_empty() {
        (k11, None)
    } else {
        let k00 = symmetrize(&(q0.transpose() * &kz * &q0));
        let k01 = q0.transpose() * &kz * &q1;
        let lu = k00.partial_piv_lu();
        let g = lu.solve(&k01); // q = −G p
        if (0..g.nrows()).any(|i| (0..g.ncols()).any(|j| !g[(i, j)].is_finite())) {
            return Err(BeamError::LinearSolve {
                reason: "massless directions without stiffness".into(),
            });
        }
        (symmetrize(&(&k11 - k01.transpose() * &g)), Some(g))
    };
    // scale by diag(b1)^{-1/2}
    let s: Vec<f64> = massive.iter().map(|&i| 1.0 / bvals[i].sqrt()).collect();
    let a = Mat::from_fn(s.len(), s.len(), |i, j| s[i] * k_eff[(i, j)] * s[j]);
    let evd = symmetrize(&a)
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| BeamError::LinearSolve { reason: format!("eigen of K: {e:?}") })?;
    let mut modes = Vec::with_capacity(s.len());
    for m in 0..s.len() {
        let lam = evd.S()[m];
        let u = evd.U();
        let p = Mat::from_fn(s.len(), 1, |i, _| u[(i, m)] * s[i]);
        let mut y = &q1 * &p;
        if let Some(g) = &recover {
            y -= &q0 * (g * &p);
        }
        let xz = &z * &y;
        let mut phi1 = vec![0.0; k * (n + 1)];
        for (i, &u) in x1.iter().enumerate() {
            phi1[u] = xz[(i, 0)];
        }
        // deterministic sign: largest-magnitude component positive
        let (mut big, mut sign) = (0.0, 1.0);
        for &v in &phi1 {
            if v.abs() > big {
                big = v.abs();
                sign = v.signum();
            }
        }
        phi1.iter_mut().for_each(|v| *v *= sign);
        modes.push(LinearMode { omega: lam.max(0.0).sqrt(), phi1 });
    }
    modes.sort_by(|a, b| a.omega.total_cmp(&b.omega));
    Ok(modes)
}

fn symmetrize(m: &Mat<f64>) -> Mat<f64> {
    Mat::from_fn(m.nrows(), m.ncols(), |i, j| 0.5 * (m[(i, j)] + m[(j, i)]))
}

/// Orthonormal basis of the null space of `a` (columns), by faer's SVD.
pub fn null_space(a: &Mat<f64>) -> Result<Mat<f64>> {
    let svd = a.svd().map_err(|e| BeamError::LinearSolve { reason: format!("SVD: {e:?}") })?;
    let s = svd.S();
    let nsv = a.nrows().min(a.ncols());
    let smax = if nsv > 0 { s[0] } else { 0.0 };
    let rank = (0..nsv).filter(|&i| s[i] > RANK_TOLERANCE * smax).count();
    let v = svd.V();
    Ok(Mat::from_fn(a.ncols(), a.ncols() - rank, |i, j| v[(i, rank + j)]))
}

/// The family of a mode of a straight beam: the component group with most kinetic energy.
pub fn family(beam: &Beam, mode: &LinearMode) -> Family {
    let k = beam.k();
    let idx = beam.components().indices();
    let mut e = [0.0f64; 6];
    for node in 0..beam.n_nodes() {
        let w = beam.mesh().weights()[node];
        for a in 0..k {
            let v = mode.phi1[node * k + a];
            // kinetic energy density by component, diagonal of M (mass-weighted)
            let m = beam.section().mass[(idx[a], idx[a])];
            e[idx[a]] += w * m * v * v;
        }
    }
    let groups = [
        (Family::Axial, e[0]),
        (Family::Torsion, e[3]),
        (Family::BendingE2, e[2] + e[4]),
        (Family::BendingE3, e[1] + e[5]),
    ];
    groups.iter().cloned().fold((Family::Axial, -1.0), |acc, g| if g.1 > acc.1 { g } else { acc }).0
}

/// Closed-form angular frequencies (first `count` non-zero) of a uniform beam.
pub mod closed_form {
    use std::f64::consts::PI;

    /// Support kinds for closed-form references.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Supports {
        /// Clamped at s = 0, free at s = L.
        ClampedFree,
        /// Pinned (translations fixed, rotations free) at s = 0, free at s = L.
        PinnedFree,
        /// Free at both ends.
        FreeFree,
    }

    /// Axial (wave speed `c`) or torsional: fixed–free `(2j−1)πc/2L`, free–free `jπc/L`.
    pub fn wave(supports: Supports, fixed: bool, c: f64, length: f64, count: usize) -> Vec<f64> {
        (1..=count)
            .map(|j| {
                let j = j as f64;
                if fixed && supports != Supports::FreeFree {
                    (2.0 * j - 1.0) * PI * c / (2.0 * length)
                } else {
                    j * PI * c / length
                }
            })
            .collect()
    }

    /// Euler–Bernoulli bending `ω_j = (β_j L)² √(EI/(m L⁴))`, with `β_j L` the roots of
    /// `cos β cosh β + 1 = 0` (clamped–free), `tan β − tanh β = 0` (pinned–free, non-zero),
    /// `cos β cosh β − 1 = 0` (free–free, non-zero), found by bisection.
    pub fn bending(supports: Supports, ei: f64, m: f64, length: f64, count: usize) -> Vec<f64> {
        let f = |b: f64| match supports {
            Supports::ClampedFree => b.cos() * b.cosh() + 1.0,
            // tan β = tanh β  ⇔  sin β cosh β − cos β sinh β = 0 (scaled by e^{−β})
            Supports::PinnedFree => (b.sin() * b.cosh() - b.cos() * b.sinh()) * (-b).exp(),
            Supports::FreeFree => (b.cos() * b.cosh() - 1.0) * (-b).exp(),
        };
        let f_scaled = |b: f64| match supports {
            Supports::ClampedFree => f(b) * (-b).exp(),
            _ => f(b),
        };
        let mut roots = Vec::new();
        // roots lie in ((j − ½)π, (j + ½)π) bracket scans on a fine grid
        let mut a = 0.5;
        let step = 0.01;
        while roots.len() < count {
            let b = a + step;
            let (fa, fb) = (f_scaled(a), f_scaled(b));
            if fa == 0.0 || fa * fb < 0.0 {
                let (mut lo, mut hi) = (a, b);
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if f_scaled(lo) * f_scaled(mid) <= 0.0 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                roots.push(0.5 * (lo + hi));
            }
            a = b;
        }
        roots.iter().map(|b| b * b * (ei / (m * length.powi(4))).sqrt()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::closed_form::*;

    #[test]
    fn bending_roots_match_tables() {
        let cf = bending(Supports::ClampedFree, 1.0, 1.0, 1.0, 2);
        assert!((cf[0] - 1.875104068711961f64.powi(2)).abs() < 1e-12);
        assert!((cf[1] - 4.694091132974175f64.powi(2)).abs() < 1e-11);
        let pf = bending(Supports::PinnedFree, 1.0, 1.0, 1.0, 1);
        assert!((pf[0] - 3.926602312047919f64.powi(2)).abs() < 1e-11);
        let ff = bending(Supports::FreeFree, 1.0, 1.0, 1.0, 1);
        assert!((ff[0] - 4.730040744862704f64.powi(2)).abs() < 1e-11);
    }
}
