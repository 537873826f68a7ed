//! Block-tridiagonal linear systems with `K×K` blocks, solved by the block LU (block Thomas)
//! recursion; every block is inverted by nalgebra's fixed-size inverse (closed-form for
//! `3×3`, LU with partial pivoting for `6×6`).
//!
//! With the unknowns and equations of one beam interleaved along the beam
//! (`x2_L, x1_0, x2_0, x1_1, …, x1_N, x2_R`, each row block next to its unknown block), the
//! implicit-midpoint step matrix couples every block only to its neighbours
//! (see [`crate::problem`]): `K = 3` for planar beams, `6` for spatial ones. The recursion is
//!
//! ```text
//! S_0 = D_0,   L_i = A_{i,i−1} S_{i−1}⁻¹,   S_i = D_i − L_i A_{i−1,i}
//! forward  y_0 = b_0,  y_i = b_i − L_i y_{i−1};   backward  x_i = S_i⁻¹ (y_i − A_{i,i+1} x_{i+1})
//! ```
//!
//! plus one optional extra block `A_{2,0}` (the single-beam left end, see
//! [`BlockTridiagonal::slot`] with `(row, col) = (2, 0)`), eliminated exactly. Pivoting
//! happens inside the blocks (partial pivoting of the `K×K` LU) but not across them: each
//! Schur complement `S_i` must be nonsingular. [`BlockTridiagonal::factorize`] checks the
//! 1-norm condition number of every `S_i` and reports a failing block instead of producing a
//! meaningless factorisation, so the caller can fall back to a pivoting sparse LU.

use nalgebra::{Const, DimMin, SMatrix, SVector};

/// Largest accepted 1-norm condition number of a Schur complement block.
///
/// Block sizes of the step matrices span ≈ 1e4 (rotary inertia vs mass, bending vs axial
/// compliance) and their Schur complements ≈ 1e6 on the bench sections; above 1e12 a block
/// solve would keep fewer than ≈ 4 significant digits and Newton would stall.
pub const MAX_BLOCK_CONDITION: f64 = 1e12;

/// Why a block factorisation was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockFailure {
    /// Block row whose Schur complement is singular or ill-conditioned.
    pub block: usize,
    /// Its 1-norm condition estimate (`∞` if exactly singular or non-finite).
    pub condition: f64,
}

type Block<const K: usize> = SMatrix<f64, K, K>;

/// A square block-tridiagonal matrix with `n` block rows of `K×K` blocks, its block LU
/// factorisation and solves.
#[derive(Clone, Debug)]
pub struct BlockTridiagonal<const K: usize> {
    n: usize,
    /// `3i`: `A_{i,i−1}`, `3i+1`: `A_{i,i}`, `3i+2`: `A_{i,i+1}`; `3n`: the extra `A_{2,0}`.
    blocks: Vec<Block<K>>,
    /// `S_i⁻¹`.
    inverse: Vec<Block<K>>,
    /// `L_i` (`L_0` unused).
    lower: Vec<Block<K>>,
    /// `A_{2,0} S_0⁻¹`.
    lower_extra: Block<K>,
    factorized: bool,
}

impl<const K: usize> BlockTridiagonal<K>
where
    Const<K>: DimMin<Const<K>, Output = Const<K>>,
{
    /// A zero matrix with `n ≥ 1` block rows.
    pub fn new(n: usize) -> Self {
        let n = n.max(1);
        Self {
            n,
            blocks: vec![Block::<K>::zeros(); 3 * n + 1],
            inverse: vec![Block::<K>::zeros(); n],
            lower: vec![Block::<K>::zeros(); n],
            lower_extra: Block::<K>::zeros(),
            factorized: false,
        }
    }

    /// Number of block rows.
    #[cfg(test)]
    pub fn n_blocks(&self) -> usize {
        self.n
    }

    /// Flat storage slot of entry `(a, b)` of block `(row, col)`, or `None` if that block is
    /// outside the band (`|row − col| > 1`, except the extra block `(2, 0)`).
    pub fn slot(&self, row: usize, col: usize, a: usize, b: usize) -> Option<usize> {
        if row >= self.n || col >= self.n || a >= K || b >= K {
            return None;
        }
        let block = if row == col + 1 {
            3 * row
        } else if row == col {
            3 * row + 1
        } else if col == row + 1 {
            3 * row + 2
        } else if row == 2 && col == 0 {
            3 * self.n
        } else {
            return None;
        };
        Some(block * K * K + b * K + a)
    }

    /// Sets every entry to zero (keeps the storage).
    pub fn clear(&mut self) {
        self.blocks.iter_mut().for_each(|b| b.fill(0.0));
        self.factorized = false;
    }

    /// Adds `value` at a slot from [`BlockTridiagonal::slot`].
    #[inline]
    pub fn add_at(&mut self, slot: usize, value: f64) {
        let kk = K * K;
        self.blocks[slot / kk].as_mut_slice()[slot % kk] += value;
        self.factorized = false;
    }

    /// Block `(row, col)` for reading (`None` outside the band).
    #[cfg(test)]
    pub fn block(&self, row: usize, col: usize) -> Option<&Block<K>> {
        self.slot(row, col, 0, 0).map(|s| &self.blocks[s / (K * K)])
    }

    /// Block `(row, col)` for writing (`None` outside the band); invalidates the factorisation.
    pub fn block_mut(&mut self, row: usize, col: usize) -> Option<&mut Block<K>> {
        let s = self.slot(row, col, 0, 0)?;
        self.factorized = false;
        Some(&mut self.blocks[s / (K * K)])
    }

    /// `S⁻¹` by nalgebra's fixed-size inverse (closed-form cofactors for `K ≤ 4`, Gaussian
    /// elimination with partial pivoting above), and the 1-norm condition of `S`.
    #[inline]
    fn invert(s: &Block<K>) -> (Block<K>, f64) {
        let inv = s.try_inverse();
        match inv {
            Some(inv) => {
                let norm1 = |m: &Block<K>| m.abs().row_sum().max();
                let cond = norm1(s) * norm1(&inv);
                (inv, if cond.is_finite() { cond } else { f64::INFINITY })
            }
            None => (Block::<K>::zeros(), f64::INFINITY),
        }
    }

    /// Block LU factorisation; fails (without panicking) if a Schur complement is singular,
    /// non-finite or has a condition number above [`MAX_BLOCK_CONDITION`].
    pub fn factorize(&mut self) -> Result<(), BlockFailure> {
        self.factorized = false;
        let n = self.n;
        let check = |i: usize, s: &Block<K>| -> Result<Block<K>, BlockFailure> {
            let (inv, cond) = Self::invert(s);
            if cond <= MAX_BLOCK_CONDITION {
                Ok(inv)
            } else {
                Err(BlockFailure { block: i, condition: cond })
            }
        };
        self.inverse[0] = check(0, &self.blocks[1])?;
        let has_extra = n > 2 && self.blocks[3 * n].iter().any(|&v| v != 0.0);
        self.lower_extra =
            if has_extra { self.blocks[3 * n] * self.inverse[0] } else { Block::<K>::zeros() };
        for i in 1..n {
            let l = if i == 2 && has_extra {
                // row 2 −= (A_20 S_0⁻¹) row 0: fills A_21 with −A_20 S_0⁻¹ A_01
                (self.blocks[3 * i] - self.lower_extra * self.blocks[2]) * self.inverse[i - 1]
            } else {
                self.blocks[3 * i] * self.inverse[i - 1]
            };
            let s = self.blocks[3 * i + 1] - l * self.blocks[3 * (i - 1) + 2];
            self.lower[i] = l;
            self.inverse[i] = check(i, &s)?;
        }
        self.factorized = true;
        Ok(())
    }

    /// Solves `A x = b` in place (`b` in block order, length `K n`); `false` if not factorised
    /// or `b` has the wrong length.
    #[cfg(test)]
    pub fn solve_in_place(&self, b: &mut [f64]) -> bool {
        if b.len() != K * self.n {
            return false;
        }
        let starts: Vec<usize> = (0..self.n).map(|i| K * i).collect();
        self.solve_in_place_at(b, &starts)
    }

    /// Solves `A x = b` in place where block `i` of both `b` and `x` occupies
    /// `v[starts[i]..starts[i] + K]` (any placement of non-overlapping blocks); `false` if not
    /// factorised or a block lies outside `v`.
    pub fn solve_in_place_at(&self, v: &mut [f64], starts: &[usize]) -> bool {
        let n = self.n;
        if !self.factorized || starts.len() != n || starts.iter().any(|&s| s + K > v.len()) {
            return false;
        }
        let get = |v: &[f64], i: usize| {
            SVector::<f64, K>::from_column_slice(&v[starts[i]..starts[i] + K])
        };
        let y0 = get(v, 0);
        let mut prev = y0;
        for i in 1..n {
            let mut y = get(v, i) - self.lower[i] * prev;
            if i == 2 {
                y -= self.lower_extra * y0;
            }
            v[starts[i]..starts[i] + K].copy_from_slice(y.as_slice());
            prev = y;
        }
        let mut next = self.inverse[n - 1] * prev;
        v[starts[n - 1]..starts[n - 1] + K].copy_from_slice(next.as_slice());
        for i in (0..n - 1).rev() {
            let x = self.inverse[i] * (get(v, i) - self.blocks[3 * i + 2] * next);
            v[starts[i]..starts[i] + K].copy_from_slice(x.as_slice());
            next = x;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::random::seeded;
    use nalgebra::DMatrix;
    use rand::Rng;

    /// Random diagonally dominant block-tridiagonal matrix (plus the extra block) solved
    /// against a dense LU: agreement to round-off.
    fn check<const K: usize>(n: usize, seed: u64)
    where
        Const<K>: DimMin<Const<K>, Output = Const<K>>,
    {
        let mut rng = seeded(seed);
        let mut m = BlockTridiagonal::<K>::new(n);
        let mut dense = DMatrix::<f64>::zeros(K * n, K * n);
        for r in 0..n {
            for c in r.saturating_sub(2)..(r + 2).min(n) {
                for a in 0..K {
                    for b in 0..K {
                        let Some(slot) = m.slot(r, c, a, b) else { continue };
                        let mut v = rng.random_range(-1.0..1.0);
                        if r == c && a == b {
                            v += 4.0 * K as f64;
                        }
                        m.add_at(slot, v);
                        dense[(K * r + a, K * c + b)] += v;
                    }
                }
            }
        }
        m.factorize().unwrap();
        let rhs: Vec<f64> = (0..K * n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut x = rhs.clone();
        assert!(m.solve_in_place(&mut x));
        let want = dense.lu().solve(&nalgebra::DVector::from_vec(rhs)).unwrap();
        let err = (nalgebra::DVector::from_vec(x) - want).amax();
        // diagonally dominant, condition O(1): round-off of O(n) operations
        assert!(err < 1e-13, "K = {K}, n = {n}: error {err}");
    }

    #[test]
    fn block_lu_matches_dense_lu() {
        for (n, seed) in [(1, 1), (2, 2), (3, 3), (7, 4), (40, 5)] {
            check::<3>(n, seed);
            check::<6>(n, seed + 10);
        }
    }

    /// A singular diagonal block (zero Schur complement) is reported, not divided by.
    #[test]
    fn singular_block_is_reported() {
        let mut m = BlockTridiagonal::<3>::new(3);
        for i in 0..3 {
            for a in 0..3 {
                m.add_at(m.slot(i, i, a, a).unwrap(), 1.0);
            }
        }
        // second block row equal to the first: S_1 = 0
        for a in 0..3 {
            m.add_at(m.slot(1, 1, a, a).unwrap(), -1.0);
            m.add_at(m.slot(1, 0, a, a).unwrap(), 1.0);
            m.add_at(m.slot(0, 1, a, a).unwrap(), 0.0);
        }
        let fail = m.factorize().unwrap_err();
        assert_eq!(fail.block, 1);
        assert!(fail.condition.is_infinite());
        let mut b = vec![1.0; 9];
        assert!(!m.solve_in_place(&mut b));
        assert!(m.slot(0, 2, 0, 0).is_none() && m.slot(2, 0, 0, 0).is_some());
    }
}
