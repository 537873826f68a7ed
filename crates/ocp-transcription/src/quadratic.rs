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

/// Where the sums of a chunk of positions go: `slot0` is the chunk's first slot (groups and
/// dense chunks numbered in evaluation order, [`Layout::slots`] in all), `pos` its positions
/// (`u32::MAX` = padding), `acc` their sums.
trait Sink {
    fn put<const W: usize>(&mut self, slot0: usize, pos: &[u32], acc: &[f64; W]);
}

/// `fx[p] += a` (the Jacobian).
struct AddTo<'a>(&'a mut [f64]);

impl Sink for AddTo<'_> {
    #[inline(always)]
    fn put<const W: usize>(&mut self, _slot0: usize, pos: &[u32], acc: &[f64; W]) {
        // padding (`u32::MAX`) is out of range: one check per lane for both
        for (&p, &a) in pos.iter().zip(acc) {
            if let Some(d) = self.0.get_mut(p as usize) {
                *d += a;
            }
        }
    }
}

/// `sums[slot] = a`: every slot's sum stored in evaluation order (the first pass of the
/// right-hand side).
struct ToSlots<'a>(&'a mut [f64]);

impl Sink for ToSlots<'_> {
    #[inline(always)]
    fn put<const W: usize>(&mut self, slot0: usize, _pos: &[u32], acc: &[f64; W]) {
        let d: &mut [f64; W] = (&mut self.0[slot0..slot0 + W]).try_into().expect("chunk width");
        *d = *acc;
    }
}

/// Rows evaluated side by side in the second pass of the right-hand side.
const RLANES: usize = 8;
/// Largest slot buffer of the two-pass right-hand side (stack), in `f64`s; a model with more
/// slots uses the single pass.
const MAX_SLOTS: usize = 4096;

/// The second pass of the right-hand side: `out_i ← fma(sum_p, x_l, out_i)` over the pairs
/// `p = (i, l)` of each row in the order in which a single pass would apply them (evaluation
/// order of the slots), as a sliced-ELLPACK layout by output row (groups of [`RLANES`] rows,
/// longest first; padding reads the slot holding `−0` and a zero `x` entry, which leaves
/// every sum as it is, sign of zero included). Each row's chain is then independent of the
/// others', where a single pass makes consecutive updates of one row wait for each other.
#[derive(Clone, Debug, Default)]
struct RowPass {
    /// Output row of each group lane (`u32::MAX` = padding).
    rows: Vec<u32>,
    /// `(offset into slot/xl, width)` of each group.
    groups: Vec<(usize, usize)>,
    slot: Vec<u32>,
    xl: Vec<u32>,
    /// Slot count of the first pass; the slot `zero` (= `slots`) holds `−0`.
    slots: usize,
}

impl RowPass {
    /// From the half layout's slots, the pairs `(i, l)` of its positions and the dimension
    /// `n` (the padding's `x` index, a zero of the padded copy of `x`).
    fn new(half: &Layout, pairs: &[(u32, u32)], n: usize) -> Self {
        let mut by_row: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n];
        for (slot, &p) in half.slot_positions().iter().enumerate() {
            if p != u32::MAX {
                let (i, l) = pairs[p as usize];
                by_row[i as usize].push((slot as u32, l));
            }
        }
        let slots = half.slots();
        let mut rows: Vec<(u32, Vec<(u32, u32)>)> = by_row
            .into_iter()
            .enumerate()
            .filter(|(_, list)| !list.is_empty())
            .map(|(i, list)| (i as u32, list))
            .collect();
        rows.sort_by_key(|r| std::cmp::Reverse(r.1.len()));
        let mut out = RowPass { slots, ..RowPass::default() };
        for chunk in rows.chunks(RLANES) {
            let width = chunk[0].1.len();
            out.groups.push((out.slot.len(), width));
            for k in 0..width {
                for lane in 0..RLANES {
                    let (sl, l) = chunk
                        .get(lane)
                        .and_then(|r| r.1.get(k))
                        .copied()
                        .unwrap_or((slots as u32, n as u32));
                    out.slot.push(sl);
                    out.xl.push(l);
                }
            }
            for lane in 0..RLANES {
                out.rows.push(chunk.get(lane).map_or(u32::MAX, |r| r.0));
            }
        }
        out
    }

    /// The second pass over the slot sums `sums` (`sums[slots] = −0`), `x` read through `xr`.
    #[inline(always)]
    fn eval(&self, sums: &[f64], xr: impl Fn(u32) -> f64, out: &mut [f64]) {
        for (g, &(off, width)) in self.groups.iter().enumerate() {
            let rows: &[u32; RLANES] =
                self.rows[g * RLANES..(g + 1) * RLANES].try_into().expect("group width");
            let mut acc = [0.0_f64; RLANES];
            for lane in 0..RLANES {
                if rows[lane] != u32::MAX {
                    acc[lane] = out[rows[lane] as usize];
                }
            }
            let (sl, xl) =
                (&self.slot[off..off + width * RLANES], &self.xl[off..off + width * RLANES]);
            for (si, li) in sl.chunks_exact(RLANES).zip(xl.chunks_exact(RLANES)) {
                for lane in 0..RLANES {
                    acc[lane] = sums[si[lane] as usize].mul_add(xr(li[lane]), acc[lane]);
                }
            }
            for lane in 0..RLANES {
                if rows[lane] != u32::MAX {
                    out[rows[lane] as usize] = acc[lane];
                }
            }
        }
    }
}

/// `out_i += x_l · sum` for every slot (single pass, for models whose slots exceed
/// [`MAX_SLOTS`] or whose dimension is not below [`PAD`]).
struct RhsSink<'a> {
    out: &'a mut [f64],
    x: &'a [f64],
    pairs: &'a [(u32, u32)],
}

impl Sink for RhsSink<'_> {
    #[inline(always)]
    fn put<const W: usize>(&mut self, _slot0: usize, pos: &[u32], acc: &[f64; W]) {
        for (&p, &a) in pos.iter().zip(acc) {
            if p != u32::MAX {
                let (i, l) = self.pairs[p as usize];
                self.out[i as usize] = a.mul_add(self.x[l as usize], self.out[i as usize]);
            }
        }
    }
}

/// Both passes of the right-hand side with a stack buffer of `CAP ≥ slots + 1` sums,
/// compiled for the best SIMD level (pulp dispatch); `x.len() < PAD`.
struct TwoPass<'a, const CAP: usize> {
    half: &'a Layout,
    rows: &'a RowPass,
    x: &'a [f64],
    out: &'a mut [f64],
}

impl<const CAP: usize> WithSimd for TwoPass<'_, CAP> {
    type Output = ();
    #[inline(always)]
    fn with_simd<T: Simd>(self, _simd: T) {
        let TwoPass { half, rows, x, out } = self;
        let mut xa = [0.0_f64; PAD];
        xa[..x.len()].copy_from_slice(x);
        let mut sums = [0.0_f64; CAP];
        half.eval(x, |j| xa[j as usize & (PAD - 1)], &mut ToSlots(&mut sums));
        sums[rows.slots] = -0.0;
        rows.eval(&sums, |j| xa[j as usize & (PAD - 1)], out);
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

    /// Number of slots of one evaluation (group lanes and dense chunk lanes, padding
    /// included), the length of the [`ToSlots`] buffer.
    fn slots(&self) -> usize {
        self.groups.len() * LANES + self.dense.iter().map(|c| c.pos.len()).sum::<usize>()
    }

    /// The position of every slot in evaluation order (`u32::MAX` = padding).
    fn slot_positions(&self) -> Vec<u32> {
        self.pos.iter().chain(self.dense.iter().flat_map(|c| &c.pos)).copied().collect()
    }

    /// Every position's sum into `sink`: the ELLPACK groups with `x` read through `xr`, then
    /// the dense clusters; each sum in ascending `x` index by fused multiply–adds.
    #[inline(always)]
    fn eval<S: Sink>(&self, x: &[f64], xr: impl Fn(u32) -> f64, sink: &mut S) {
        let mut slot = 0;
        for (g, &(off, width)) in self.groups.iter().enumerate() {
            let mut acc = [0.0_f64; LANES];
            let (idx, val) =
                (&self.idx[off..off + width * LANES], &self.val[off..off + width * LANES]);
            for (ix, v) in idx.chunks_exact(LANES).zip(val.chunks_exact(LANES)) {
                for lane in 0..LANES {
                    acc[lane] = v[lane].mul_add(xr(ix[lane]), acc[lane]);
                }
            }
            sink.put(slot, &self.pos[g * LANES..(g + 1) * LANES], &acc);
            slot += LANES;
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
                sink.put(slot, pos, &acc);
                slot += DLANES;
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
    /// The second pass of the right-hand side (by output row).
    rows: RowPass,
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
        let half = Layout::new(half_contrib);
        Ok(Self {
            n,
            terms: terms.iter().map(|&(i, l, j, v)| (ix(i), ix(l), ix(j), v)).collect(),
            jac: Layout::new(contrib),
            rows: RowPass::new(&half, &pairs, n),
            half,
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
    /// `out_i += x_l · sum` by a fused multiply–add, each row's pairs in a fixed order. The
    /// sums go to a stack buffer first and the rows are then updated side by side
    /// (`RowPass`); models beyond its size update `out` as each sum is formed (same order,
    /// same bits).
    pub fn add_rhs(&self, x: &[f64], out: &mut [f64]) {
        assert_eq!(out.len(), self.n, "out must have length n");
        assert_eq!(x.len(), self.n, "x must have length n");
        let (half, rows) = (&self.half, &self.rows);
        // the buffer is zeroed at every call: the smallest of a few sizes that holds the slots
        if self.n < PAD && rows.slots < 1024 {
            Arch::new().dispatch(TwoPass::<1024> { half, rows, x, out });
        } else if self.n < PAD && rows.slots < 1536 {
            Arch::new().dispatch(TwoPass::<1536> { half, rows, x, out });
        } else if self.n < PAD && rows.slots < 2048 {
            Arch::new().dispatch(TwoPass::<2048> { half, rows, x, out });
        } else if self.n < PAD && rows.slots < MAX_SLOTS {
            Arch::new().dispatch(TwoPass::<MAX_SLOTS> { half, rows, x, out });
        } else {
            self.half.eval_dispatch(x, &mut RhsSink { out, x, pairs: &self.pairs });
        }
    }

    /// The single-pass right-hand side (every sum applied to `out` as it is formed); the
    /// reference of the two-pass [`QuadraticTerms::add_rhs`] in the tests.
    #[cfg(test)]
    fn add_rhs_single_pass(&self, x: &[f64], out: &mut [f64]) {
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

    /// The two-pass right-hand side gives the single pass's bits (same fused multiply–adds
    /// in the same order per row), on random and class-structured terms, with a nonzero `out`
    /// to add to (and an exact `−0` in it, which the padding must keep).
    #[test]
    fn two_pass_rhs_matches_the_single_pass_bit_for_bit() {
        for (n, structured) in [(7, false), (61, false), (48, true), (53, true)] {
            let mut rng = seeded(11 + n as u64);
            let class: Vec<usize> = (0..n).map(|_| rng.random_range(0..4)).collect();
            let mut terms = Vec::new();
            if structured {
                for i in 0..n {
                    for l in 0..n {
                        for j in l..n {
                            if class[i] ^ class[l] ^ class[j] == 0
                                && rng.random_range(0.0..1.0) < 0.6
                            {
                                terms.push((i, l, j, rng.random_range(-1.0..1.0)));
                            }
                        }
                    }
                }
            } else {
                for _ in 0..20 * n {
                    let (i, l, j) =
                        (rng.random_range(0..n), rng.random_range(0..n), rng.random_range(0..n));
                    terms.push((i, l, j, rng.random_range(-1.0..1.0)));
                }
            }
            let q = QuadraticTerms::new(n, &terms).unwrap();
            assert!(q.rows.slots < MAX_SLOTS, "n = {n}: two-pass path");
            for trial in 0..4 {
                let x: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
                let mut a: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
                if trial == 0 {
                    a.fill(-0.0);
                }
                let mut b = a.clone();
                q.add_rhs(&x, &mut a);
                q.add_rhs_single_pass(&x, &mut b);
                for i in 0..n {
                    assert_eq!(a[i].to_bits(), b[i].to_bits(), "n = {n}, row {i}");
                }
            }
        }
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
