//! The second-order modal problem of `docs/theory.md §4` (eqs. 30–32) as sparse entries:
//! `B1`, `B2`, `D`, `G1` split out of the full FE operators, and compressed rows to apply them.

use crate::error::{invalid, Result};
use crate::layout::{FullIndex, Layout};

/// The second-order problem of theory.md §4 as `(row, col, value)` entries in assembly order
/// (duplicates summed when used): `B1` (n1 × n1), `B2` (n2 × n2), `D` (n1 × n2), `G1`
/// (`g_rows` × n1).
#[derive(Clone, Debug, PartialEq)]
pub struct SparseProblem {
    /// Length of `X1`.
    pub n1: usize,
    /// Length of `X2`.
    pub n2: usize,
    /// Entries of `B1`.
    pub b1: Vec<(usize, usize, f64)>,
    /// Entries of `B2`.
    pub b2: Vec<(usize, usize, f64)>,
    /// Entries of `D`.
    pub d: Vec<(usize, usize, f64)>,
    /// Rows of `G1`.
    pub g_rows: usize,
    /// Entries of `G1`.
    pub g1: Vec<(usize, usize, f64)>,
}

impl SparseProblem {
    /// Splits the full FE operators (ordering of theory.md §2) into `B1`, `B2`, `D`, `G1`; see
    /// [`crate::SecondOrderProblem::from_full_entries`] for the rules and checks.
    pub fn from_full_entries(
        layout: &Layout,
        b: impl IntoIterator<Item = (usize, usize, f64)>,
        a: impl IntoIterator<Item = (usize, usize, f64)>,
        g_rows: usize,
        g: impl IntoIterator<Item = (usize, usize, f64)>,
    ) -> Result<Self> {
        let (n1, n2, nf) = (layout.n1(), layout.n2(), layout.n_full());
        let cls = |i: usize, what: &str| -> Result<FullIndex> {
            match layout.classify_full(i) {
                FullIndex::OutOfRange => {
                    Err(invalid(what, i, format!("index past the FE vector length {nf}")))
                }
                c => Ok(c),
            }
        };
        let (mut b1, mut b2, mut d, mut dt) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (i, j, v) in b {
            match (cls(i, "B row")?, cls(j, "B column")?) {
                (FullIndex::X1(p), FullIndex::X1(q)) => b1.push((p, q, v)),
                (FullIndex::X2(p), FullIndex::X2(q)) => b2.push((p, q, v)),
                _ if v == 0.0 => {}
                _ => {
                    return Err(invalid(
                        format!("B[({i}, {j})]"),
                        v,
                        "B must be block diagonal (nodes, elements, zero on end values)",
                    ))
                }
            }
        }
        for (i, j, v) in a {
            match (cls(i, "A row")?, cls(j, "A column")?) {
                (FullIndex::X1(p), FullIndex::X2(q)) => d.push((p, q, v)),
                (FullIndex::X2(p), FullIndex::X1(q)) => dt.push((q, p, v)),
                _ => {}
            }
        }
        // A skew: D + (element block)ᵀ = 0 entry by entry, to 1e-12 of max |D|.
        let ds = Csr::new(n1, n2, &d);
        let dts = Csr::new(n1, n2, &dt);
        let scale = ds.max_abs().max(f64::MIN_POSITIVE);
        for p in 0..n1 {
            let (a, b) = (ds.row(p), dts.row(p));
            let mut cols: Vec<usize> = a.iter().chain(&b).map(|e| e.0).collect();
            cols.sort_unstable();
            cols.dedup();
            for q in cols {
                let find = |r: &[(usize, f64)]| r.iter().find(|e| e.0 == q).map_or(0.0, |e| e.1);
                let (x, y) = (find(&a), find(&b));
                if (x + y).abs() > 1e-12 * scale {
                    return Err(invalid(
                        format!("A (node {p}, element {q})"),
                        x,
                        format!("A must be skew: the element-row entry is {y}"),
                    ));
                }
            }
        }
        let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); g_rows];
        let mut kinds = vec![(false, false); g_rows];
        for (i, j, v) in g {
            if i >= g_rows {
                return Err(invalid("G row", i, format!("G has {g_rows} rows")));
            }
            if v == 0.0 {
                continue;
            }
            match cls(j, "G column")? {
                FullIndex::X1(q) => {
                    rows[i].push((q, v));
                    kinds[i].0 = true;
                }
                FullIndex::End => kinds[i].1 = true,
                _ => {
                    return Err(invalid(
                        format!("G[({i}, {j})]"),
                        v,
                        "constraint rows on element values are not supported",
                    ))
                }
            }
        }
        let kept: Vec<usize> = (0..g_rows).filter(|&r| kinds[r].0).collect();
        if let Some(&r) = kept.iter().find(|&&r| kinds[r].1) {
            return Err(invalid(
                format!("G row {r}"),
                "mixed",
                "a row mixes node velocities and end values",
            ));
        }
        let mut g1 = Vec::new();
        for (new, &r) in kept.iter().enumerate() {
            g1.extend(rows[r].iter().map(|&(q, v)| (new, q, v)));
        }
        Ok(SparseProblem { n1, n2, b1, b2, d, g_rows: kept.len(), g1 })
    }
}

/// A sparse matrix in compressed rows (duplicates summed in entry order).
#[derive(Clone, Debug)]
pub(crate) struct Csr {
    nrows: usize,
    ncols: usize,
    ptr: Vec<usize>,
    idx: Vec<usize>,
    val: Vec<f64>,
}

impl Csr {
    /// From `(row, col, value)` entries, all inside `nrows × ncols`.
    pub(crate) fn new(nrows: usize, ncols: usize, entries: &[(usize, usize, f64)]) -> Self {
        let mut order: Vec<usize> = (0..entries.len()).collect();
        order.sort_by_key(|&e| (entries[e].0, entries[e].1)); // stable: entry order on ties
        let mut ptr = vec![0usize; nrows + 1];
        let (mut idx, mut val): (Vec<usize>, Vec<f64>) = (Vec::new(), Vec::new());
        let mut last = (usize::MAX, usize::MAX);
        for e in order {
            let (r, c, v) = entries[e];
            if (r, c) == last {
                *val.last_mut().expect("an entry before") += v;
            } else {
                idx.push(c);
                val.push(0.0 + v);
                ptr[r + 1] += 1;
                last = (r, c);
            }
        }
        for r in 0..nrows {
            ptr[r + 1] += ptr[r];
        }
        Csr { nrows, ncols, ptr, idx, val }
    }

    pub(crate) fn nrows(&self) -> usize {
        self.nrows
    }

    pub(crate) fn ncols(&self) -> usize {
        self.ncols
    }

    /// Row `r` as `(col, value)` pairs.
    pub(crate) fn row(&self, r: usize) -> Vec<(usize, f64)> {
        (self.ptr[r]..self.ptr[r + 1]).map(|p| (self.idx[p], self.val[p])).collect()
    }

    /// Largest `|entry|`.
    pub(crate) fn max_abs(&self) -> f64 {
        self.val.iter().fold(0.0f64, |a, v| a.max(v.abs()))
    }

    /// `y = A x`.
    pub(crate) fn matvec(&self, x: &[f64], y: &mut [f64]) {
        for r in 0..self.nrows {
            y[r] = (self.ptr[r]..self.ptr[r + 1]).map(|p| self.val[p] * x[self.idx[p]]).sum();
        }
    }

    /// `y = Aᵀ x`.
    pub(crate) fn tmatvec(&self, x: &[f64], y: &mut [f64]) {
        y.iter_mut().for_each(|v| *v = 0.0);
        for r in 0..self.nrows {
            for p in self.ptr[r]..self.ptr[r + 1] {
                y[self.idx[p]] += self.val[p] * x[r];
            }
        }
    }
}
