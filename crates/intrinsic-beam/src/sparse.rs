//! A square sparse system with a fixed pattern: triplet values are scattered into CSC storage
//! through a precomputed slot map, the symbolic LU (faer) is computed once and reused for every
//! numeric factorisation.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::lu::{factorize_symbolic_lu, LuSymbolicParams, NumericLu, SymbolicLu};
pub use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{Pair, SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Par};

use crate::error::{BeamError, Result};

/// Fixed-pattern sparse matrix with a reusable LU factorisation.
pub struct SparseLuSystem {
    n: usize,
    symbolic: SymbolicSparseColMat<usize>,
    slots: Vec<usize>,
    values: Vec<f64>,
    lu_symbolic: SymbolicLu<usize>,
    numeric: NumericLu<usize, f64>,
    buffer: MemBuffer,
    factorized: bool,
    /// Number of numeric factorisations done.
    pub factorizations: usize,
}

impl std::fmt::Debug for SparseLuSystem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseLuSystem")
            .field("n", &self.n)
            .field("nnz", &self.values.len())
            .field("factorizations", &self.factorizations)
            .finish()
    }
}

impl SparseLuSystem {
    /// Builds the structure from `(row, col)` entries (duplicates are summed).
    ///
    /// ```
    /// use intrinsic_beam::SparseLuSystem;
    ///
    /// // [[2, 1], [0, 4]] x = [4, 8]: the pattern once, then values in pattern order
    /// let mut lu = SparseLuSystem::new(2, &[(0, 0), (0, 1), (1, 1)])?;
    /// lu.factorize(&[2.0, 1.0, 4.0])?;
    /// let mut x = vec![4.0, 8.0];
    /// lu.solve(&mut x)?;
    /// assert!((x[0] - 1.0).abs() < 1e-15 && (x[1] - 2.0).abs() < 1e-15);
    /// # Ok::<(), intrinsic_beam::BeamError>(())
    /// ```
    pub fn new(n: usize, pattern: &[(usize, usize)]) -> Result<Self> {
        Self::with_threshold(n, pattern, SupernodalThreshold::AUTO)
    }

    /// As [`SparseLuSystem::new`] with an explicit simplicial/supernodal choice.
    pub fn with_threshold(
        n: usize,
        pattern: &[(usize, usize)],
        threshold: SupernodalThreshold,
    ) -> Result<Self> {
        let pairs: Vec<Pair<usize, usize>> =
            pattern.iter().map(|&(r, c)| Pair::new(r, c)).collect();
        let (symbolic, _) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| BeamError::LinearSolve { reason: format!("sparse pattern: {e:?}") })?;
        let col_ptr = symbolic.col_ptr();
        let row_idx = symbolic.row_idx();
        let slots = pattern
            .iter()
            .map(|&(r, c)| {
                let (start, end) = (col_ptr[c], col_ptr[c + 1]);
                start + row_idx[start..end].binary_search(&r).expect("entry is in the pattern")
            })
            .collect();
        let nnz = row_idx.len();
        let params =
            LuSymbolicParams { supernodal_flop_ratio_threshold: threshold, ..Default::default() };
        let lu_symbolic = factorize_symbolic_lu(symbolic.as_ref(), params)
            .map_err(|e| BeamError::LinearSolve { reason: format!("symbolic LU: {e:?}") })?;
        let req = StackReq::any_of(&[
            lu_symbolic.factorize_numeric_lu_scratch::<f64>(Par::Seq, Default::default()),
            lu_symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        Ok(Self {
            n,
            symbolic,
            slots,
            values: vec![0.0; nnz],
            lu_symbolic,
            numeric: NumericLu::new(),
            buffer: MemBuffer::new(req),
            factorized: false,
            factorizations: 0,
        })
    }

    /// Size of the system.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Factorises the matrix whose entries (in pattern order) are `entries`.
    pub fn factorize(&mut self, entries: &[f64]) -> Result<()> {
        self.values.iter_mut().for_each(|v| *v = 0.0);
        for (&slot, &v) in self.slots.iter().zip(entries) {
            self.values[slot] += v;
        }
        let mat = SparseColMatRef::new(self.symbolic.as_ref(), &self.values);
        self.factorized = false;
        self.lu_symbolic
            .factorize_numeric_lu(
                &mut self.numeric,
                mat,
                Par::Seq,
                MemStack::new(&mut self.buffer),
                Default::default(),
            )
            .map_err(|e| BeamError::LinearSolve { reason: format!("numeric LU: {e:?}") })?;
        self.factorized = true;
        self.factorizations += 1;
        Ok(())
    }

    /// Solves `A x = rhs` in place with the last factorisation.
    pub fn solve(&mut self, rhs: &mut [f64]) -> Result<()> {
        if !self.factorized {
            return Err(BeamError::LinearSolve { reason: "no factorisation available".into() });
        }
        let lu = faer::sparse::linalg::lu::LuRef::new_unchecked(&self.lu_symbolic, &self.numeric);
        let n = self.n;
        let mat = MatMut::from_column_major_slice_mut(rhs, n, 1);
        lu.solve_in_place_with_conj(Conj::No, mat, Par::Seq, MemStack::new(&mut self.buffer));
        if rhs.iter().any(|v| !v.is_finite()) {
            return Err(BeamError::LinearSolve {
                reason: "singular step matrix (non-finite solution)".into(),
            });
        }
        Ok(())
    }
}
