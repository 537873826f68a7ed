//! [`QuadraticTerms`]: the nonlinear part `N(x)x` of a modal model as a list of bilinear
//! terms, with a fast, allocation-free Jacobian kernel.
//!
//! A quadratic right-hand side `f_i += v x_l x_j` (the modal ROM's `Γ` tensors, paper
//! eqs. 14–21) has a Jacobian that is a sparse *linear* map of `x`: position `(i, l)` gets
//! `v x_j`, position `(i, j)` gets `v x_l`. Forming it is the most expensive part of a
//! sensitivity stage (≈ 2·(number of terms) multiply–adds with gathers of `x`). The terms are
//! grouped by Jacobian position and stored in a sliced-ELLPACK layout (positions sorted by
//! term count, groups of 8 positions evaluated side by side, padded with zero terms), so the
//! eight accumulators of a group are independent and the kernel, compiled for the best SIMD
//! level available at run time (pulp dispatch), has no dependency chains. `x` is read from a
//! zero-padded stack copy indexed with a mask, so no bounds check is left in the loop.
//! Positions whose contributions read a common small set of `x` entries (a modal ROM's
//! selection rules make whole classes of positions share one) are evaluated densely instead
//! (`DenseCluster`: contiguous values times one broadcast `x` entry, no gathers). The
//! right-hand side uses the same sliced-ELLPACK layout grouped by output row.
//! Results are bit-for-bit deterministic (each position's sum is accumulated in a fixed
//! order by fused multiply–adds, which are exactly rounded on every dispatch path).

use crate::error::{invalid, Result};
use faer::traits::pulp::{Arch, Simd, WithSimd};

/// Positions evaluated side by side.
const LANES: usize = 8;
/// Stack copy of `x` for dimensions up to this (larger models use bounds-checked reads).
const PAD: usize = 128;
/// Positions per chunk of a dense cluster.
const DLANES: usize = 16;
/// Largest support (distinct `x` entries read) of a dense cluster.
const MAX_SUPPORT: usize = 16;

/// Jacobian positions whose contributions read a few common `x` entries (`support`), stored
/// densely: in chunks of [`DLANES`] positions, for every support entry the values of the
/// chunk's positions side by side (zero where a position has no contribution), so that the
/// kernel multiplies contiguous values by one broadcast `x` entry (no gathers). A modal ROM's
/// selection rules make the supports of whole position classes coincide.
#[derive(Clone, Debug, Default)]
struct DenseCluster {
    support: Vec<u32>,
    /// Position of each chunk lane (`u32::MAX` = padding).
    pos: Vec<u32>,
    /// Per chunk: `support.len() × DLANES` values, support-entry major.
    val: Vec<f64>,
}

/// Sums `Σ_c v_c x_{j_c}` of many positions, each over its own contributions `(j_c, v_c)`:
/// dense clusters plus a sliced-ELLPACK layout for the rest.
#[derive(Clone, Debug, Default)]
struct Layout {
    /// Position of each group lane (`u32::MAX` = padding).
    pos: Vec<u32>,
    /// `(offset into idx/val, width)` of each group.
    groups: Vec<(usize, usize)>,
    idx: Vec<u32>,
    val: Vec<f64>,
    /// Positions evaluated densely (the others are in `groups`).
    dense: Vec<DenseCluster>,
}

/// Where a position's sum goes.
trait Sink {
    fn put(&mut self, p: u32, a: f64);
}

/// `fx[p] += a` (the Jacobian).
struct AddTo<'a>(&'a mut [f64]);

impl Sink for AddTo<'_> {
    #[inline(always)]
    fn put(&mut self, p: u32, a: f64) {
        self.0[p as usize] += a;
    }
}

/// `out[i] += a x_l` with `(i, l) = pairs[p]` (the right-hand side from the row sums
/// `Σ_j v x_j` of the pairs `(i, l)`).
struct RhsSink<'a> {
    out: &'a mut [f64],
    x: &'a [f64],
    pairs: &'a [(u32, u32)],
}

impl Sink for RhsSink<'_> {
    #[inline(always)]
    fn put(&mut self, p: u32, a: f64) {
        let (i, l) = self.pairs[p as usize];
        self.out[i as usize] = a.mul_add(self.x[l as usize], self.out[i as usize]);
    }
}

#[inline(always)]
fn scatter<S: Sink>(pos: &[u32], acc: &[f64], sink: &mut S) {
    for (&p, &a) in pos.iter().zip(acc) {
        if p != u32::MAX {
            sink.put(p, a);
        }
    }
}

impl Layout {
    /// From contributions `(position, x index, value)`.
    fn new(mut contrib: Vec<(u32, u32, f64)>) -> Self {
        contrib.sort_by_key(|c| (c.0, c.1));
        let mut rows: Vec<Row> = Vec::new();
        for (p, j, v) in contrib {
            match rows.last_mut() {
                Some((q, list)) if *q == p => list.push((j, v)),
                _ => rows.push((p, vec![(j, v)])),
            }
        }
        let (dense, mut rows) = dense_clusters(rows);
        let mut out = Layout { dense, ..Layout::default() };
        // longest first (stable on position), so each group's padding is small
        rows.sort_by_key(|r| std::cmp::Reverse(r.1.len()));
        for chunk in rows.chunks(LANES) {
            let width = chunk[0].1.len();
            out.groups.push((out.idx.len(), width));
            for slot in 0..width {
                for lane in 0..LANES {
                    let (j, v) =
                        chunk.get(lane).and_then(|r| r.1.get(slot)).copied().unwrap_or((0, 0.0));
                    out.idx.push(j);
                    out.val.push(v);
                }
            }
            for lane in 0..LANES {
                out.pos.push(chunk.get(lane).map_or(u32::MAX, |r| r.0));
            }
        }
        out
    }

    /// Structurally nonzero positions.
    fn positions(&self) -> usize {
        self.pos
            .iter()
            .chain(self.dense.iter().flat_map(|c| &c.pos))
            .filter(|&&p| p != u32::MAX)
            .count()
    }

    /// Every position's sum into `sink`: the ELLPACK groups with `x` read through `xr`, then
    /// the dense clusters; each sum in ascending `x` index by fused multiply–adds.
    #[inline(always)]
    fn eval<S: Sink>(&self, x: &[f64], xr: impl Fn(u32) -> f64, sink: &mut S) {
        for (g, &(off, width)) in self.groups.iter().enumerate() {
            let mut acc = [0.0_f64; LANES];
            let (idx, val) =
                (&self.idx[off..off + width * LANES], &self.val[off..off + width * LANES]);
            for (ix, v) in idx.chunks_exact(LANES).zip(val.chunks_exact(LANES)) {
                for lane in 0..LANES {
                    acc[lane] = v[lane].mul_add(xr(ix[lane]), acc[lane]);
                }
            }
            scatter(&self.pos[g * LANES..(g + 1) * LANES], &acc, sink);
        }
        for c in &self.dense {
            let k = c.support.len();
            let mut xs = [0.0_f64; MAX_SUPPORT];
            for (t, &j) in c.support.iter().enumerate() {
                xs[t] = x[j as usize];
            }
            for (pos, vals) in c.pos.chunks_exact(DLANES).zip(c.val.chunks_exact(k * DLANES)) {
                let mut acc = [0.0_f64; DLANES];
                for (col, &xv) in vals.chunks_exact(DLANES).zip(&xs[..k]) {
                    let col: &[f64; DLANES] = col.try_into().expect("chunk width");
                    for lane in 0..DLANES {
                        acc[lane] = col[lane].mul_add(xv, acc[lane]);
                    }
                }
                scatter(pos, &acc, sink);
            }
        }
    }

    /// [`Layout::eval`], compiled for the best SIMD level (pulp dispatch) with `x` from a
    /// zero-padded stack copy indexed by a mask when `n ≤ PAD` (no bounds checks), with
    /// bounds-checked reads otherwise.
    fn eval_dispatch<S: Sink>(&self, x: &[f64], sink: &mut S) {
        struct Kernel<'a, S> {
            layout: &'a Layout,
            x: &'a [f64],
            sink: &'a mut S,
        }
        impl<S: Sink> WithSimd for Kernel<'_, S> {
            type Output = ();
            #[inline(always)]
            fn with_simd<T: Simd>(self, _simd: T) {
                let Kernel { layout, x, sink } = self;
                let mut xa = [0.0_f64; PAD];
                xa[..x.len()].copy_from_slice(x);
                layout.eval(x, |j| xa[j as usize & (PAD - 1)], sink);
            }
        }
        if x.len() <= PAD {
            Arch::new().dispatch(Kernel { layout: self, x, sink });
        } else {
            self.eval(x, |j| x[j as usize], sink);
        }
    }
}

/// Bilinear terms `f_i += v x_l x_j` of an `n`-dimensional state, with their Jacobian map.
#[derive(Clone, Debug, Default)]
pub struct QuadraticTerms {
    n: usize,
    terms: Vec<(u32, u32, u32, f64)>,
    /// The Jacobian: position `i + l n` sums `v x_j` over the terms `(i, l, j)` and `(i, j, l)`.
    jac: Layout,
    /// The right-hand side's row sums: position `p` (the pair `pairs[p] = (i, l)`) sums
    /// `v x_j` over the terms `(i, l, j)`; then `f_i += x_l · sum`.
    half: Layout,
    pairs: Vec<(u32, u32)>,
}

impl QuadraticTerms {
    /// From terms `(i, l, j, v)`: `f_i += v x_l x_j` (`i, l, j < n`, `v` finite; repeated and
    /// symmetric pairs are allowed, they add up).
    pub fn new(n: usize, terms: &[(usize, usize, usize, f64)]) -> Result<Self> {
        if n >= u32::MAX as usize || n.checked_mul(n).is_none_or(|nn| nn >= u32::MAX as usize) {
            return Err(invalid("n", n, "n² must be below 2^32"));
        }
        for (t, &(i, l, j, v)) in terms.iter().enumerate() {
            if i >= n || l >= n || j >= n {
                return Err(invalid(
                    "terms",
                    format!("({i}, {l}, {j}) at {t} (n = {n})"),
                    "indices must be below n",
                ));
            }
            if !v.is_finite() {
                return Err(invalid("terms", format!("value {v} at {t}"), "must be finite"));
            }
        }
        let ix = |v: usize| v as u32;
        // Jacobian contributions (position, x index, value)
        let mut contrib: Vec<(u32, u32, f64)> = Vec::with_capacity(2 * terms.len());
        for &(i, l, j, v) in terms {
            contrib.push((ix(i + l * n), ix(j), v));
            contrib.push((ix(i + j * n), ix(l), v));
        }
        // right-hand side: pairs (i, l) numbered in column-major order
        let mut pairs: Vec<(u32, u32)> = terms.iter().map(|&(i, l, _, _)| (ix(i), ix(l))).collect();
        pairs.sort_by_key(|&(i, l)| (l, i));
        pairs.dedup();
        let half_contrib = terms
            .iter()
            .map(|&(i, l, j, v)| {
                let p = pairs
                    .binary_search_by_key(&(ix(l), ix(i)), |&(pi, pl)| (pl, pi))
                    .expect("pair of the term");
                (ix(p), ix(j), v)
            })
            .collect();
        Ok(Self {
            n,
            terms: terms.iter().map(|&(i, l, j, v)| (ix(i), ix(l), ix(j), v)).collect(),
            jac: Layout::new(contrib),
            half: Layout::new(half_contrib),
            pairs,
        })
    }

    /// State dimension `n`.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Number of terms.
    pub fn len(&self) -> usize {
        self.terms.len()
    }

    /// Whether there are no terms.
    pub fn is_empty(&self) -> bool {
        self.terms.is_empty()
    }

    /// Number of structurally nonzero Jacobian positions.
    pub fn jacobian_nonzeros(&self) -> usize {
        self.jac.positions()
    }

    /// `out_i += Σ v x_l x_j` (`x`, `out` of length `n`): for every pair `(i, l)` the sum
    /// `Σ_j v x_j` (the Jacobian's layout: dense clusters and ELLPACK groups), then
    /// `out_i += x_l · sum` by a fused multiply–add, pairs in a fixed order.
    pub fn add_rhs(&self, x: &[f64], out: &mut [f64]) {
        assert_eq!(out.len(), self.n, "out must have length n");
        assert_eq!(x.len(), self.n, "x must have length n");
        self.half.eval_dispatch(x, &mut RhsSink { out, x, pairs: &self.pairs });
    }

    /// `fx += ∂(N(x)x)/∂x` into the column-major `n × n` slice `fx`.
    pub fn add_jacobian(&self, x: &[f64], fx: &mut [f64]) {
        assert_eq!(fx.len(), self.n * self.n, "fx must be n × n");
        assert_eq!(x.len(), self.n, "x must have length n");
        self.jac.eval_dispatch(x, &mut AddTo(fx));
    }

    /// `out += Σ_i w_i ∇²(N(x)x)_i` (symmetric, `out` is at least `n × n`, column-major with
    /// leading dimension `ld`).
    pub fn add_weighted_hessian(&self, w: &[f64], out: &mut [f64], ld: usize) {
        for &(i, l, j, v) in &self.terms {
            let (l, j) = (l as usize, j as usize);
            let c = w[i as usize] * v;
            out[l + j * ld] += c;
            out[j + l * ld] += c;
        }
    }
}

/// A position's contributions `(x index, value)`, ascending in the index.
type Row = (u32, Vec<(u32, f64)>);

/// Splits the positions into dense clusters (greedy: positions by decreasing support size
/// join the cluster whose support they overlap most when the union stays within
/// [`MAX_SUPPORT`] and at least half of their support is shared; a cluster is kept when it
/// has at least [`LANES`] positions and at least half of its dense entries are contributions)
/// and the rest, returned for the sparse layout.
fn dense_clusters(rows: Vec<Row>) -> (Vec<DenseCluster>, Vec<Row>) {
    let support = |r: &Row| {
        let mut s: Vec<u32> = r.1.iter().map(|c| c.0).collect();
        s.dedup();
        s
    };
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by_key(|&r| (std::cmp::Reverse(support(&rows[r]).len()), rows[r].0));
    // (support union, members)
    let mut clusters: Vec<(Vec<u32>, Vec<usize>)> = Vec::new();
    let mut sparse = vec![false; rows.len()];
    for r in order {
        let sup = support(&rows[r]);
        if sup.len() > MAX_SUPPORT {
            sparse[r] = true;
            continue;
        }
        let mut best: Option<(usize, usize)> = None;
        for (c, (u, _)) in clusters.iter().enumerate() {
            let new = sup.iter().filter(|j| u.binary_search(j).is_err()).count();
            if u.len() + new <= MAX_SUPPORT
                && 2 * new <= sup.len()
                && best.is_none_or(|(_, b)| new < b)
            {
                best = Some((c, new));
                if new == 0 {
                    break;
                }
            }
        }
        match best {
            Some((c, _)) => {
                let (u, members) = &mut clusters[c];
                for j in sup {
                    if let Err(at) = u.binary_search(&j) {
                        u.insert(at, j);
                    }
                }
                members.push(r);
            }
            None => clusters.push((sup, vec![r])),
        }
    }
    let mut dense = Vec::new();
    for (u, mut members) in clusters {
        let entries: usize = members.iter().map(|&r| support(&rows[r]).len()).sum();
        if members.len() < LANES || 2 * entries < members.len() * u.len() {
            for r in members {
                sparse[r] = true;
            }
            continue;
        }
        members.sort_by_key(|&r| rows[r].0);
        let k = u.len();
        let mut c = DenseCluster { support: u, ..DenseCluster::default() };
        for chunk in members.chunks(DLANES) {
            let base = c.val.len();
            c.val.resize(base + k * DLANES, 0.0);
            for (lane, &r) in chunk.iter().enumerate() {
                for &(j, v) in &rows[r].1 {
                    let t = c.support.binary_search(&j).expect("support of the cluster");
                    c.val[base + t * DLANES + lane] += v;
                }
            }
            for lane in 0..DLANES {
                c.pos.push(chunk.get(lane).map_or(u32::MAX, |&r| rows[r].0));
            }
        }
        dense.push(c);
    }
    let rest = rows.into_iter().zip(sparse).filter(|(_, s)| *s).map(|(r, _)| r).collect();
    (dense, rest)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::seeded;
    use rand::Rng;

    /// The Jacobian kernel (both paths) against a direct evaluation of the term list, and the
    /// right-hand side against Euler's identity `J(x)x = 2N(x)x`.
    #[test]
    fn jacobian_matches_the_term_list() {
        for n in [7, 61, 130] {
            let mut rng = seeded(n as u64);
            let terms: Vec<(usize, usize, usize, f64)> = (0..20 * n)
                .map(|_| {
                    (
                        rng.random_range(0..n),
                        rng.random_range(0..n),
                        rng.random_range(0..n),
                        rng.random_range(-1.0..1.0),
                    )
                })
                .collect();
            let q = QuadraticTerms::new(n, &terms).unwrap();
            let x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            // sums of ≤ ~60 terms of size ≤ 1: round-off ≤ 1e-13
            let fx = jacobian_against_terms(&q, &terms, &x, n);
            let mut f = vec![0.0; n];
            q.add_rhs(&x, &mut f);
            let mut f_direct = vec![0.0; n];
            for &(i, l, j, v) in &terms {
                f_direct[i] += v * x[l] * x[j];
            }
            let dev = f.iter().zip(&f_direct).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(dev < 1e-13, "n = {n}: rhs {dev}");
            for i in 0..n {
                let jx: f64 = (0..n).map(|c| fx[i + c * n] * x[c]).sum();
                assert!((jx - 2.0 * f[i]).abs() < 1e-12, "n = {n}, row {i}");
            }
        }
        assert!(QuadraticTerms::new(3, &[(0, 3, 1, 1.0)]).is_err());
    }

    /// `q`'s Jacobian at `x` against the term list summed directly (to 1e-13); returns it.
    fn jacobian_against_terms(
        q: &QuadraticTerms,
        terms: &[(usize, usize, usize, f64)],
        x: &[f64],
        n: usize,
    ) -> Vec<f64> {
        let mut fx = vec![0.0; n * n];
        q.add_jacobian(x, &mut fx);
        let mut direct = vec![0.0; n * n];
        for &(i, l, j, v) in terms {
            direct[i + l * n] += v * x[j];
            direct[i + j * n] += v * x[l];
        }
        let dev = fx.iter().zip(&direct).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(dev < 1e-13, "n = {n}: {dev}");
        fx
    }

    /// Terms under a selection rule (4 symmetry classes, `c_i ⊕ c_l ⊕ c_j = 0`, as a modal
    /// ROM's): the positions' supports coincide by class, most positions go to dense
    /// clusters, and the Jacobian still matches the term list.
    #[test]
    fn class_structured_terms_use_dense_clusters() {
        let n = 48;
        let mut rng = seeded(3);
        let class: Vec<usize> = (0..n).map(|_| rng.random_range(0..4)).collect();
        let mut terms = Vec::new();
        for i in 0..n {
            for l in 0..n {
                for j in l..n {
                    if class[i] ^ class[l] ^ class[j] == 0 && rng.random_range(0.0..1.0) < 0.8 {
                        terms.push((i, l, j, rng.random_range(-1.0..1.0)));
                    }
                }
            }
        }
        let q = QuadraticTerms::new(n, &terms).unwrap();
        let dense: usize =
            q.jac.dense.iter().flat_map(|c| &c.pos).filter(|&&p| p != u32::MAX).count();
        assert!(dense * 2 > q.jacobian_nonzeros(), "{dense} of {}", q.jacobian_nonzeros());
        let x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
        jacobian_against_terms(&q, &terms, &x, n);
        assert!(QuadraticTerms::new(3, &[(0, 1, 1, f64::NAN)]).is_err());
    }
}
