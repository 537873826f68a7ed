//! Lanczos iteration with full reorthogonalisation for the largest eigenvalues of an operator
//! `S` that is self-adjoint in a positive semidefinite inner product `⟨x, y⟩ = xᵀ B y`
//! (the shift-inverted modal pencil of `docs/theory.md §4`, eqs. 31–32).
//!
//! With `V_m = [v_0 … v_{m−1}]` `B`-orthonormal, `S V_m = V_m T_m + β_m v_m e_mᵀ` with `T_m`
//! tridiagonal (`α_j = ⟨v_j, S v_j⟩`, `β_j = ‖S v_j − α_j v_j − β_{j−1} v_{j−1}‖`). Each new
//! vector is orthogonalised against all previous ones (classical Gram–Schmidt, twice), and
//! against the given deflation vectors, so `V_m` stays orthonormal to round-off; the Ritz pairs
//! are those of the whole projected matrix `H_m = V_mᵀ B S V_m` (`T_m` up to round-off),
//! assembled from the reorthogonalisation coefficients. A Ritz pair `(θ_i, V_m s_i)` has
//! residual `‖S x_i − θ_i x_i‖_B ≤ Σ_l |b_l s_{l,i}|` over the remainders `b_l` of `S v_l` left
//! outside the basis (`β_m` of the last step, and those dropped at a restart); it counts as
//! converged when that is at most `tol · |θ_i|`. For a `B`-self-adjoint `S` an eigenvalue of
//! `S` then lies within `tol · |θ_i|` of `θ_i`.
//!
//! The start vector is a fixed pseudo-random sequence (same bits every run), mapped once by
//! `S` so that it lies in the range of `S` (where `B` is definite: the massless directions of a
//! singular `B` are those `S` eliminates). On a breakdown (`β_m` at round-off: an invariant
//! subspace), and once after the first convergence (one start vector sees one copy of a
//! repeated eigenvalue only; at least `nev` more steps follow), the iteration continues from the next vector of the sequence,
//! orthogonalised against the basis; when that vector has nothing left outside the basis, the
//! space is exhausted and every Ritz pair is exact.

use crate::error::{ModalError, Result};
use faer::{Mat, Side};

/// An operator `S`, self-adjoint in the inner product of `B`.
pub(crate) trait Operator {
    /// Length of the vectors.
    fn n(&self) -> usize;
    /// `y = S x`.
    fn apply(&mut self, x: &[f64], y: &mut [f64]) -> Result<()>;
    /// `y = B x`.
    fn inner(&self, x: &[f64], y: &mut [f64]);
}

/// Converged Ritz pairs, largest `θ` first.
pub(crate) struct RitzPairs {
    /// Ritz values `θ`, decreasing.
    pub theta: Vec<f64>,
    /// Ritz vectors, `B`-orthonormal.
    pub vectors: Vec<Vec<f64>>,
    /// Lanczos steps taken.
    pub steps: usize,
    /// Whether every returned pair met the tolerance (or the space was exhausted).
    pub converged: bool,
}

/// Fixed pseudo-random vector number `seed` (a 64-bit linear congruential sequence), entries
/// in `[−0.5, 0.5)`.
pub(crate) fn start_vector(n: usize, seed: u64) -> Vec<f64> {
    let mut s = 0x9E37_79B9_7F4A_7C15u64 ^ seed.wrapping_mul(0xD1B5_4A32_D192_ED03);
    (0..n)
        .map(|_| {
            s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        })
        .collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Orthogonalises `w` against the deflation pairs `(q, Bq)` and the basis `v` (twice), returning
/// the coefficients on `v` summed over both passes.
fn orthogonalise(
    op: &dyn Operator,
    w: &mut [f64],
    deflate: &[(Vec<f64>, Vec<f64>)],
    v: &[Vec<f64>],
    bw: &mut [f64],
) -> Vec<f64> {
    let mut h = vec![0.0; v.len()];
    for _ in 0..2 {
        for (q, bq) in deflate {
            let c = dot(bq, w);
            w.iter_mut().zip(q).for_each(|(x, y)| *x -= c * y);
        }
        op.inner(w, bw);
        let coef: Vec<f64> = v.iter().map(|vi| dot(vi, bw)).collect();
        for (vi, c) in v.iter().zip(&coef) {
            w.iter_mut().zip(vi).for_each(|(x, y)| *x -= c * y);
        }
        h.iter_mut().zip(&coef).for_each(|(a, c)| *a += c);
    }
    h
}

fn b_norm(op: &dyn Operator, w: &[f64], bw: &mut [f64]) -> f64 {
    op.inner(w, bw);
    dot(w, bw).max(0.0).sqrt()
}

/// Eigen decomposition of the projected matrix `H = Vᵀ B S V` (symmetric; `hcols[l]` holds
/// `⟨v_i, S v_l⟩` for `i ≤ l`): eigenvalues decreasing, with the matching eigenvectors as
/// columns.
fn projected_eigen(hcols: &[Vec<f64>]) -> Result<(Vec<f64>, Mat<f64>)> {
    let m = hcols.len();
    let t = Mat::from_fn(m, m, |i, j| if i <= j { hcols[j][i] } else { hcols[i][j] });
    let eig = t.self_adjoint_eigen(Side::Lower).map_err(|e| ModalError::Numerical {
        stage: "eigen of the projected Lanczos matrix".into(),
        reason: format!("{e:?}"),
    })?;
    let s = eig.S().column_vector();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| s[b].total_cmp(&s[a]).then(a.cmp(&b)));
    let u = eig.U();
    Ok((order.iter().map(|&i| s[i]).collect(), Mat::from_fn(m, m, |r, c| u[(r, order[c])])))
}

/// Residual bounds `Σ_l |b_l s_{l,i}|` of the first `k` Ritz vectors, over the remainders `b_l`
/// of `S v_l` left outside the basis (the last step's and those dropped at a restart).
fn estimates(s: &Mat<f64>, lost: &[(usize, f64)], k: usize) -> Vec<f64> {
    (0..k).map(|i| lost.iter().map(|&(l, b)| (b * s[(l, i)]).abs()).sum()).collect()
}

/// The `nev` largest eigenpairs of `op` in the `B`-orthogonal complement of `deflate`
/// (`(q, Bq)` pairs, `B`-orthonormal), by at most `max_steps` Lanczos steps (see the module
/// docs). Fewer than `nev` pairs come back when the space has fewer dimensions.
///
/// The Ritz pairs come from the whole projected matrix `Vᵀ B S V` (the coefficients of the
/// full reorthogonalisation), so the iteration may restart from a new vector of the start
/// sequence: it does so on a breakdown and once after the first convergence, so that a second
/// copy of a repeated eigenvalue (invisible from one start vector) is found too.
pub(crate) fn largest(
    op: &mut dyn Operator,
    deflate: &[(Vec<f64>, Vec<f64>)],
    nev: usize,
    tol: f64,
    max_steps: usize,
) -> Result<RitzPairs> {
    let n = op.n();
    let mut bw = vec![0.0; n];
    let mut v: Vec<Vec<f64>> = Vec::new();
    let mut hcols: Vec<Vec<f64>> = Vec::new();
    // remainders of S v_l dropped at restarts: (l, norm)
    let mut lost: Vec<(usize, f64)> = Vec::new();
    let mut seed = 0u64;
    // A new start direction from the fixed sequence, in the range of S and orthogonal to what
    // is there; `None` when nothing is left (the space is exhausted).
    let mut fresh = |op: &mut dyn Operator, v: &[Vec<f64>], bw: &mut [f64]| -> Result<_> {
        for _ in 0..3 {
            let x = start_vector(n, seed);
            seed += 1;
            let mut w = vec![0.0; n];
            op.apply(&x, &mut w)?;
            let n0 = b_norm(op, &w, bw);
            if n0 == 0.0 {
                continue;
            }
            orthogonalise(op, &mut w, deflate, v, bw);
            let nrm = b_norm(op, &w, bw);
            if nrm > 1e-8 * n0 {
                w.iter_mut().for_each(|x| *x /= nrm);
                return Ok(Some(w));
            }
        }
        Ok(None)
    };
    let Some(first) = fresh(op, &v, &mut bw)? else {
        return Ok(RitzPairs { theta: vec![], vectors: vec![], steps: 0, converged: true });
    };
    v.push(first);
    let mut w = vec![0.0; n];
    let mut exhausted = false;
    let mut restarted = false;
    let mut restart_at = 0;
    let mut last: f64;
    loop {
        let j = v.len() - 1;
        op.apply(&v[j], &mut w)?;
        let h = orthogonalise(op, &mut w, deflate, &v, &mut bw);
        let scale = h[j].abs().max(hcols.iter().fold(0.0f64, |a, c| a.max(c[c.len() - 1].abs())));
        hcols.push(h);
        let b = b_norm(op, &w, &mut bw);
        last = b;
        let breakdown = b <= 1e-13 * scale;
        let m = v.len();
        let mut restart = breakdown;
        if breakdown || m >= max_steps || (m >= nev && (m - nev) % 5 == 0) {
            let (theta, s) = projected_eigen(&hcols)?;
            let k = nev.min(m);
            let mut bounds = lost.clone();
            bounds.push((m - 1, if breakdown { 0.0 } else { b }));
            let est = estimates(&s, &bounds, k);
            let done = (0..k).all(|i| est[i] <= tol * theta[i].abs());
            if m >= max_steps || (done && k == nev && restarted && m >= restart_at + nev) {
                break;
            }
            if done && k == nev && !restarted {
                restarted = true;
                restart_at = m;
                restart = true;
            }
        }
        if restart {
            match fresh(op, &v, &mut bw)? {
                Some(x) => {
                    lost.push((m - 1, if breakdown { 0.0 } else { b }));
                    v.push(x);
                }
                None => {
                    exhausted = true;
                    last = 0.0;
                    break;
                }
            }
        } else {
            w.iter_mut().for_each(|x| *x /= b);
            v.push(std::mem::replace(&mut w, vec![0.0; n]));
        }
    }
    let m = v.len();
    let (theta, s) = projected_eigen(&hcols)?;
    let k = nev.min(m);
    let mut bounds = lost;
    bounds.push((m - 1, last));
    let est = estimates(&s, &bounds, k);
    let mut vectors = Vec::with_capacity(k);
    for i in 0..k {
        let mut x = vec![0.0; n];
        for (j, vj) in v.iter().enumerate() {
            let c = s[(j, i)];
            x.iter_mut().zip(vj).for_each(|(a, b)| *a += c * b);
        }
        vectors.push(x);
    }
    let converged = exhausted || (0..k).all(|i| est[i] <= tol * theta[i].abs());
    Ok(RitzPairs { theta: theta[..k].to_vec(), vectors, steps: m, converged })
}
