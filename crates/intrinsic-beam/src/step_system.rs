//! The linear solver of a single beam's implicit-midpoint step system (beam rows plus `2k`
//! end rows): a block-tridiagonal block LU on the unknowns interleaved along the beam when the
//! step pattern allows it and every block is well conditioned, faer's sparse LU otherwise.
//!
//! # Interleaved order
//! Block position (each `k` unknowns and the `k` rows solved next to them):
//!
//! ```text
//! 0:      left end rows      | the unknown each end row constrains (x1_0[a] or x2_L[a])
//! 1:      node-0 rows        | the other one of x1_0[a], x2_L[a]
//! 2e+2:   element-e rows     | x2_e                       (e = 0…N−1)
//! 2n+1:   node-n rows        | x1_n                       (n = 1…N)
//! 2N+2:   right end rows     | x2_R
//! ```
//!
//! Node rows touch `x2_{n−1}, x1_n, x2_n` and element rows `x1_e, x2_e, x1_{e+1}`: neighbours
//! only. The one exception, element 0's column `x1_0[a]` of a velocity-controlled left end
//! component (position 0), is the extra block `A_{2,0}` of [`BlockTridiagonal`]. Without flux
//! damping (`D1 = D2 = 0`) the whole pattern fits; with it node rows reach `x1_{n±1}` two
//! blocks away and the sparse LU is used.
//!
//! # Why no pivoting across blocks
//! Position 0 is the identity on the constrained end unknowns. For sections with positive
//! definite `M` and `C` the rest is a principal submatrix of `B/dt − μ(A + ∂f_nl)` (plus the
//! `∓I` end columns): its symmetric part `B/dt` is positive definite up to the gyroscopic and
//! sectional-force terms, which are `O(dt ‖x‖)` relative, and Schur complements of a matrix
//! with positive definite symmetric part keep one, so every `S_i` is nonsingular. Rigid or
//! massless directions (DAE sections) can make a block singular (e.g. a massless rotation at a
//! free left end, or the rigid/massless out-of-plane directions of a spatial paper section);
//! [`BlockTridiagonal::factorize`] detects it and the solver switches to the sparse LU (partial
//! pivoting) for the rest of the run. An inaccurate factorisation cannot change the converged
//! step either: Newton stops on the residual's fixed point, the factorisation only sets its
//! speed.

use nalgebra::{Const, DimMin, Matrix6, SMatrix, SVector};

use crate::beam::StepInput;
use crate::block_tridiagonal::BlockTridiagonal;
use crate::error::{BeamError, Result};
use crate::kernels::{Kernels, PlanarKernels, SpatialKernels};
use crate::operators::{halves, tilde};
use crate::problem::{BeamProblem, End};
use crate::sparse::SparseLuSystem;

/// Which linear solver the implicit-midpoint step uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LinearSolver {
    /// Block-tridiagonal block LU when the step pattern fits (no `D1`/`D2` flux damping) and
    /// every block is well conditioned, faer sparse LU otherwise (default).
    #[default]
    Auto,
    /// Always faer's sparse LU (partial pivoting).
    SparseLu,
}

/// A block-tridiagonal matrix plus the maps from the step system's triplets and rows/columns.
#[derive(Clone, Debug)]
struct Interleaved<const K: usize> {
    matrix: BlockTridiagonal<K>,
    /// Storage slot of every step-pattern entry (building it checks that the pattern fits).
    #[cfg_attr(not(test), allow(dead_code))]
    slots: Vec<usize>,
    /// Offset of each position's rows (= columns, up to `swaps`) in the step vector.
    starts: Vec<usize>,
    /// Pairs `(x2_L[a], x1_0[a])` to swap after a solve (velocity-controlled left end).
    swaps: Vec<(usize, usize)>,
    /// Inverse maps: block-order position of step-system row / unknown `i`.
    row_pos: Vec<usize>,
    col_pos: Vec<usize>,
    /// `M`, `C`, `D0` restricted to the active components.
    mass: SMatrix<f64, K, K>,
    compliance: SMatrix<f64, K, K>,
    d0: SMatrix<f64, K, K>,
    /// Midpoint weights `μ` of the unknowns, per node (`x1`) and per element (`x2`).
    mu_node: Vec<SVector<f64, K>>,
    mu_element: Vec<SVector<f64, K>>,
}

impl<const K: usize> Interleaved<K>
where
    Const<K>: DimMin<Const<K>, Output = Const<K>>,
{
    /// `None` if a pattern entry falls outside the band.
    fn new(problem: &BeamProblem, pattern: &[(usize, usize)]) -> Option<Self> {
        let beam = &problem.beam;
        let n = beam.n_elements();
        let rows = beam.n_rows();
        let dim = problem.dim();
        let mut row_of = vec![0; dim];
        let mut col_of = vec![0; dim];
        for a in 0..K {
            let constrained = problem.end_unknown(End::Left, a);
            let other = if constrained == beam.x1_index(0, a) {
                beam.left_index(a)
            } else {
                beam.x1_index(0, a)
            };
            row_of[a] = rows + a;
            col_of[a] = constrained;
            row_of[K + a] = a;
            col_of[K + a] = other;
            for node in 1..=n {
                row_of[K * (2 * node + 1) + a] = beam.x1_index(node, a);
                col_of[K * (2 * node + 1) + a] = beam.x1_index(node, a);
            }
            for e in 0..n {
                row_of[K * (2 * e + 2) + a] = beam.x2_index(e, a);
                col_of[K * (2 * e + 2) + a] = beam.x2_index(e, a);
            }
            row_of[K * (2 * n + 2) + a] = rows + K + a;
            col_of[K * (2 * n + 2) + a] = beam.right_index(a);
        }
        let invert = |map: &[usize]| {
            let mut inv = vec![0; map.len()];
            for (i, &m) in map.iter().enumerate() {
                inv[m] = i;
            }
            inv
        };
        let (row_pos, col_pos) = (invert(&row_of), invert(&col_of));
        let matrix = BlockTridiagonal::<K>::new(2 * n + 3);
        let slots = pattern
            .iter()
            .map(|&(r, c)| {
                let (p, q) = (row_pos[r], col_pos[c]);
                matrix.slot(p / K, q / K, p % K, q % K)
            })
            .collect::<Option<Vec<_>>>()?;
        let restrict = |m: &Matrix6<f64>| {
            SMatrix::<f64, K, K>::from_fn(|a, b| beam.components().entry(m, a, b))
        };
        let section = beam.section();
        let mu = |start: usize| SVector::<f64, K>::from_fn(|a, _| beam.midpoint_weight(start + a));
        let starts: Vec<usize> = (0..2 * n + 3).map(|p| row_of[K * p]).collect();
        let contiguous = (0..2 * n + 3).all(|p| {
            (0..K).all(|a| {
                row_of[K * p + a] == starts[p] + a && (p < 2 || col_of[K * p + a] == starts[p] + a)
            })
        });
        let swaps: Vec<(usize, usize)> = (0..K)
            .filter(|&a| col_of[a] != row_of[a])
            .map(|a| (row_of[a], row_of[K + a]))
            .collect();
        if !contiguous {
            return None;
        }
        Some(Self {
            starts,
            swaps,
            matrix,
            slots,
            mass: restrict(&section.mass),
            compliance: restrict(&section.compliance),
            d0: restrict(&section.d0),
            mu_node: (0..=n).map(|node| mu(beam.x1_index(node, 0))).collect(),
            mu_element: (0..n).map(|e| mu(beam.x2_index(e, 0))).collect(),
            row_pos,
            col_pos,
        })
    }

    /// Adds `value` at step-system entry `(row, col)` (must lie in the band).
    fn add_entry(&mut self, row: usize, col: usize, value: f64) {
        let (p, q) = (self.row_pos[row], self.col_pos[col]);
        let slot = self.matrix.slot(p / K, q / K, p % K, q % K).expect("entry in the band");
        self.matrix.add_at(slot, value);
    }

    /// Adds a `K×K` block at step-system rows `row0..row0+K`, columns `col0..col0+K`
    /// (entry-wise: for blocks whose rows or columns are permuted at the left end).
    fn add_block_entries(&mut self, row0: usize, col0: usize, blk: &SMatrix<f64, K, K>) {
        for b in 0..K {
            for a in 0..K {
                self.add_entry(row0 + a, col0 + b, blk[(a, b)]);
            }
        }
    }

    /// Sets block position `(p, q)` to `blk`.
    fn set_block(&mut self, p: usize, q: usize, blk: SMatrix<f64, K, K>) {
        *self.matrix.block_mut(p, q).expect("block in the band") = blk;
    }

    /// Assembles the step Jacobian `∂(step residual)/∂new` (beam rows and end rows, no flux
    /// damping) directly into the blocks: the same matrix as [`crate::beam::Beam::jacobian_values`]
    /// plus the unit end rows, computed on `K`-vectors. Columns are scaled by the midpoint
    /// weights `μ` (`∂mid/∂new`), and `B/dt` is added on the diagonal blocks.
    fn assemble<O: Kernels<K>>(
        &mut self,
        ops: &O,
        problem: &BeamProblem,
        input: &StepInput<'_>,
        mid: &[f64],
    ) {
        let beam = &problem.beam;
        let n = beam.n_elements();
        let dt = input.dt;
        let (hs, ws) = (beam.mesh().lengths(), beam.mesh().weights());
        let (m, c) = (self.mass, self.compliance);
        let has_d0 = self.d0.iter().any(|&v| v != 0.0);
        let eye = SMatrix::<f64, K, K>::identity();
        let unit = |b: usize| SVector::<f64, K>::from_fn(|a, _| if a == b { 1.0 } else { 0.0 });
        let get = |i: usize| SVector::<f64, K>::from_column_slice(&mid[i..i + K]);
        let scale = |mut blk: SMatrix<f64, K, K>, mu: &SVector<f64, K>| {
            for b in 0..K {
                blk.column_mut(b).scale_mut(mu[b]);
            }
            blk
        };
        // dead loads: ∂(T_midᵀ G)/∂ω_mid ≈ (dt/2) tilde(local value) (as in jacobian_values)
        let dead = if input.loads.has_dead() {
            let rot = beam.midpoint_rotations(input, mid);
            beam.node_loads(input.time + 0.5 * dt, input.loads, &rot).1
        } else {
            Vec::new()
        };
        self.matrix.clear();
        // node rows: −∂f/∂x1_n (gyroscopic, D0, dead loads), μ-scaled, plus w M/dt
        for node in 0..=n {
            let x1 = get(beam.x1_index(node, 0));
            let mx1 = m * x1;
            let w = ws[node];
            let mut g = SMatrix::<f64, K, K>::from_fn(|_, _| 0.0);
            for b in 0..K {
                let mb: SVector<f64, K> = m.column(b).into_owned();
                let col = (ops.l1_times(&unit(b), &mx1) + ops.l1_times(&x1, &mb)) * w;
                g.set_column(b, &col);
            }
            if has_d0 {
                g -= self.d0 * w;
            }
            if !dead.is_empty() {
                let (fd, md) = halves(&dead[node]);
                let mut t = Matrix6::zeros();
                t.fixed_view_mut::<3, 3>(0, 3).copy_from(&(tilde(&fd) * (0.5 * dt)));
                t.fixed_view_mut::<3, 3>(3, 3).copy_from(&(tilde(&md) * (0.5 * dt)));
                g -= SMatrix::<f64, K, K>::from_fn(|a, b| beam.components().entry(&t, a, b));
            }
            let blk = scale(g, &self.mu_node[node]) + m * (w / dt);
            if node == 0 {
                self.add_block_entries(0, beam.x1_index(0, 0), &blk);
            } else {
                self.set_block(2 * node + 1, 2 * node + 1, blk);
            }
        }
        // element e: node-row blocks of x2_e and the element rows
        for e in 0..n {
            let h = hs[e];
            let x2 = get(beam.x2_index(e, 0));
            let cx2 = c * x2;
            let xb = (get(beam.x1_index(e, 0)) + get(beam.x1_index(e + 1, 0))) * 0.5;
            let mut dq = SMatrix::<f64, K, K>::from_fn(|_, _| 0.0);
            let mut j = dq;
            let mut d22 = dq;
            for b in 0..K {
                let eb = unit(b);
                let ceb: SVector<f64, K> = c.column(b).into_owned();
                let col = ops.e_times(&eb) - ops.l2_times(&eb, &cx2) - ops.l2_times(&x2, &ceb);
                dq.set_column(b, &(col * (0.5 * h)));
                let col = ops.l1t_times(&eb, &cx2) - ops.et_times(&eb);
                j.set_column(b, &(col * (0.5 * h)));
                d22.set_column(b, &(ops.l1t_times(&xb, &ceb) * (-h)));
            }
            let mu2 = self.mu_element[e];
            let p = 2 * e + 2;
            // node e (position p − 1) and node e + 1 (position p + 1), column x2_e
            self.set_block(p - 1, p, scale(-eye - dq, &mu2));
            self.set_block(p + 1, p, scale(eye - dq, &mu2));
            // element rows
            self.set_block(p, p, scale(d22, &mu2) + c * (h / dt));
            let left = scale(eye - j, &self.mu_node[e]);
            if e == 0 {
                self.add_block_entries(beam.x2_index(0, 0), beam.x1_index(0, 0), &left);
            } else {
                self.set_block(p, p - 1, left);
            }
            self.set_block(p, p + 1, scale(-eye - j, &self.mu_node[e + 1]));
        }
        // end columns of nodes 0 and N (μ = 1), end rows
        for a in 0..K {
            self.add_entry(beam.x1_index(0, a), beam.left_index(a), 1.0);
            self.add_entry(beam.x1_index(n, a), beam.right_index(a), -1.0);
            let rows = beam.n_rows();
            self.add_entry(rows + a, problem.end_unknown(End::Left, a), 1.0);
            self.add_entry(rows + K + a, problem.end_unknown(End::Right, a), 1.0);
        }
    }

    /// Block LU of the matrix given by triplet values in step-pattern order (the generic
    /// route; [`Interleaved::assemble`] writes the same blocks directly).
    #[cfg(test)]
    fn factorize(&mut self, values: &[f64]) -> bool {
        self.matrix.clear();
        for (&slot, &v) in self.slots.iter().zip(values) {
            self.matrix.add_at(slot, v);
        }
        self.matrix.factorize().is_ok()
    }

    fn solve(&mut self, rhs: &mut [f64]) -> bool {
        // Every position's rows and columns are the same contiguous index range, except at
        // the left end: position 0 reads the end rows (at x2_L) and position 1 the node-0 rows
        // (at x1_0), but a velocity-controlled component `a` has x1_0[a] at position 0 and
        // x2_L[a] at position 1: their solution entries are swapped back afterwards.
        if !self.matrix.solve_in_place_at(rhs, &self.starts) {
            return false;
        }
        for &(i, j) in &self.swaps {
            rhs.swap(i, j);
        }
        true
    }
}

#[derive(Clone, Debug)]
enum Block {
    Planar(Box<Interleaved<3>>),
    Spatial(Box<Interleaved<6>>),
}

/// The step system's factorisation: block-tridiagonal if possible, sparse LU otherwise.
#[derive(Debug)]
pub(crate) struct StepSolver {
    dim: usize,
    pattern: Vec<(usize, usize)>,
    block: Option<Block>,
    sparse: Option<SparseLuSystem>,
    /// Whether the current factorisation is the block one.
    block_active: bool,
    factorized: bool,
    /// Factorisations refused by the block LU (done by the sparse LU instead).
    pub(crate) block_refusals: usize,
    /// Midpoint buffer of [`StepSolver::refresh`].
    mid: Vec<f64>,
}

impl StepSolver {
    /// Builds the solver for `problem`'s step pattern.
    pub(crate) fn new(problem: &BeamProblem, choice: LinearSolver) -> Result<Self> {
        let pattern = problem.step_pattern();
        let block = match (choice, problem.beam.k()) {
            (LinearSolver::SparseLu, _) => None,
            (LinearSolver::Auto, 3) => {
                Interleaved::<3>::new(problem, &pattern).map(|b| Block::Planar(Box::new(b)))
            }
            (LinearSolver::Auto, 6) => {
                Interleaved::<6>::new(problem, &pattern).map(|b| Block::Spatial(Box::new(b)))
            }
            _ => None,
        };
        let sparse = match block {
            Some(_) => None,
            None => Some(SparseLuSystem::new(problem.dim(), &pattern)?),
        };
        Ok(Self {
            dim: problem.dim(),
            pattern,
            block,
            sparse,
            block_active: false,
            factorized: false,
            block_refusals: 0,
            mid: vec![0.0; problem.dim()],
        })
    }

    /// Number of step-pattern entries (length of the values passed to `factorize`).
    pub(crate) fn nnz(&self) -> usize {
        self.pattern.len()
    }

    /// Whether the block-tridiagonal path applies (it may still refuse a factorisation).
    pub(crate) fn is_block(&self) -> bool {
        self.block.is_some()
    }

    /// Name of the solver of the current (or next) factorisation.
    pub(crate) fn name(&self) -> &'static str {
        match (&self.block, self.block_active || !self.factorized) {
            (Some(Block::Planar(_)), true) => "block-tridiagonal (3x3 blocks)",
            (Some(Block::Spatial(_)), true) => "block-tridiagonal (6x6 blocks)",
            _ => "faer sparse LU",
        }
    }

    /// Evaluates and factorises the step Jacobian at `new` (step from `old` with `input`):
    /// directly into the blocks when the block path applies, else (or when the block LU
    /// refuses a block) as triplets in `values` (length [`StepSolver::nnz`]) for the sparse LU.
    pub(crate) fn refresh(
        &mut self,
        problem: &BeamProblem,
        input: &StepInput<'_>,
        old: &[f64],
        new: &[f64],
        values: &mut [f64],
    ) -> Result<()> {
        self.factorized = false;
        self.block_active = false;
        if let Some(block) = self.block.as_mut() {
            problem.beam.check_input(input)?;
            let mid = &mut self.mid;
            problem.beam.midpoint(old, new, mid)?;
            let kappa0 = problem.beam.section().kappa0;
            let ok = match block {
                Block::Planar(b) => {
                    b.assemble(&PlanarKernels { kappa: kappa0.y }, problem, input, mid);
                    b.matrix.factorize().is_ok()
                }
                Block::Spatial(b) => {
                    b.assemble(&SpatialKernels { kappa0 }, problem, input, mid);
                    b.matrix.factorize().is_ok()
                }
            };
            if ok {
                self.block_active = true;
                self.factorized = true;
                return Ok(());
            }
            // a singular or ill-conditioned Schur block comes from the section (rigid or
            // massless directions) or the end rows and recurs: sparse LU from now on
            self.block_refusals += 1;
            self.block = None;
        }
        let nnz_beam = problem.beam.jacobian_nnz();
        problem.beam.jacobian_values(input, old, new, &mut values[..nnz_beam])?;
        values[nnz_beam..].iter_mut().for_each(|v| *v = 1.0);
        if self.sparse.is_none() {
            self.sparse = Some(SparseLuSystem::new(self.dim, &self.pattern)?);
        }
        if let Some(sparse) = self.sparse.as_mut() {
            sparse.factorize(values)?;
        }
        self.factorized = true;
        Ok(())
    }

    /// Factorises the matrix with entries `values` in step-pattern order (block LU if it
    /// applies and accepts every block, sparse LU otherwise).
    #[cfg(test)]
    pub(crate) fn factorize(&mut self, values: &[f64]) -> Result<()> {
        self.factorized = false;
        let ok = match &mut self.block {
            Some(Block::Planar(b)) => b.factorize(values),
            Some(Block::Spatial(b)) => b.factorize(values),
            None => false,
        };
        if self.block.is_some() && !ok {
            self.block_refusals += 1;
            self.block = None;
        }
        self.block_active = ok;
        if !ok {
            if self.sparse.is_none() {
                self.sparse = Some(SparseLuSystem::new(self.dim, &self.pattern)?);
            }
            if let Some(sparse) = self.sparse.as_mut() {
                sparse.factorize(values)?;
            }
        }
        self.factorized = true;
        Ok(())
    }

    /// Solves with the current factorisation, in place.
    pub(crate) fn solve(&mut self, rhs: &mut [f64]) -> Result<()> {
        if !self.factorized {
            return Err(BeamError::LinearSolve { reason: "no factorisation available".into() });
        }
        if self.block_active {
            let ok = match &mut self.block {
                Some(Block::Planar(b)) => b.solve(rhs),
                Some(Block::Spatial(b)) => b.solve(rhs),
                None => false,
            };
            if !ok || rhs.iter().any(|v| !v.is_finite()) {
                return Err(BeamError::LinearSolve {
                    reason: "block-tridiagonal solve gave a non-finite solution".into(),
                });
            }
            return Ok(());
        }
        match self.sparse.as_mut() {
            Some(s) => s.solve(rhs),
            None => Err(BeamError::LinearSolve { reason: "no factorisation available".into() }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::beam::Beam;
    use crate::components::Components;
    use crate::kinematics::Kinematics;
    use crate::loads::{Amplitude, LoadFrame, Loads, PointLoad};
    use crate::mesh::Mesh;
    use crate::problem::EndCondition;
    use crate::samples;
    use crate::samples::random::{
        random_load, random_rotations, random_section, random_vec, seeded,
    };
    use nalgebra::{DMatrix, DVector, Vector6};

    /// A random curved beam with `D0` (no flux damping), dead and follower loads, rotated
    /// kinematics and the given end conditions; random old/new states.
    fn setup(
        seed: u64,
        components: Components,
        left: EndCondition,
        right: EndCondition,
    ) -> (BeamProblem, Kinematics, Vec<f64>, Vec<f64>) {
        let mut rng = seeded(seed);
        let mut section = random_section(&mut rng, components, true, true);
        section.d1 = Matrix6::zeros();
        section.d2 = Matrix6::zeros();
        let beam = Beam::new(section, Mesh::graded(1.3, 6, 2.0).unwrap(), components).unwrap();
        let mut loads = Loads::none();
        for (node, frame) in [(6, LoadFrame::Dead), (2, LoadFrame::Follower), (0, LoadFrame::Dead)]
        {
            loads.point.push(PointLoad {
                node,
                frame,
                value: random_load(&mut rng, components),
                amplitude: Amplitude::Constant,
            });
        }
        let mut kin = Kinematics::straight(&beam);
        random_rotations(&mut rng, &mut kin, components);
        let old = random_vec(&mut rng, beam.dim());
        let new = random_vec(&mut rng, beam.dim());
        (BeamProblem::new(beam, left, right, loads).unwrap(), kin, old, new)
    }

    fn ends() -> Vec<(EndCondition, EndCondition)> {
        let mixed = EndCondition::Mixed {
            velocity: [true, false, false, true, true, false],
            value: Vector6::new(0.1, 0.0, 0.3, 0.0, 0.5, 0.0),
            amplitude: Amplitude::Constant,
        };
        vec![
            (EndCondition::Clamped, EndCondition::Free),
            (EndCondition::Free, EndCondition::Clamped),
            (mixed.clone(), EndCondition::Pinned),
            (EndCondition::Pinned, mixed),
        ]
    }

    fn max_block_difference<const K: usize>(a: &Interleaved<K>, b: &Interleaved<K>) -> f64
    where
        Const<K>: DimMin<Const<K>, Output = Const<K>>,
    {
        let n = a.matrix.n_blocks();
        let mut worst = 0.0f64;
        for r in 0..n {
            for c in r.saturating_sub(2)..(r + 2).min(n) {
                if let (Some(x), Some(y)) = (a.matrix.block(r, c), b.matrix.block(r, c)) {
                    worst = worst.max((x - y).amax());
                }
            }
        }
        worst
    }

    /// The blocks written directly on `K`-vectors equal the beam's generic Jacobian
    /// (`jacobian_values`, 6-component kernels) scattered through the step pattern, for
    /// planar and spatial beams, curved sections with `D0`, dead/follower loads and all kinds
    /// of end rows (clamped, free, pinned, mixed: the permuted left-end blocks).
    #[test]
    fn direct_blocks_match_the_triplet_jacobian() {
        for (i, (left, right)) in ends().into_iter().enumerate() {
            for components in [Components::Planar, Components::Spatial] {
                let (problem, kin, old, new) =
                    setup(40 + i as u64, components, left.clone(), right.clone());
                let input = StepInput {
                    time: 0.2,
                    dt: 0.05,
                    loads: &problem.loads,
                    node_quaternions: &kin.xi,
                };
                let mut solver = StepSolver::new(&problem, LinearSolver::Auto).unwrap();
                let values = values(&problem, &kin, &old, &new);
                assert_eq!(values.len(), solver.nnz());
                let mut mid = vec![0.0; problem.dim()];
                problem.beam.midpoint(&old, &new, &mut mid).unwrap();
                let kappa0 = problem.beam.section().kappa0;
                let diff = match solver.block.as_mut().unwrap() {
                    Block::Planar(b) => {
                        let mut t = b.clone();
                        t.factorize(&values);
                        b.assemble(&PlanarKernels { kappa: kappa0.y }, &problem, &input, &mid);
                        max_block_difference(b, &t)
                    }
                    Block::Spatial(b) => {
                        let mut t = b.clone();
                        t.factorize(&values);
                        b.assemble(&SpatialKernels { kappa0 }, &problem, &input, &mid);
                        max_block_difference(b, &t)
                    }
                };
                // same formulas, different association of O(1)-O(100) terms: round-off
                assert!(diff < 1e-12, "{components:?}, ends {i}: block difference {diff}");
            }
        }
    }

    /// The step matrix assembled densely from the pattern and values.
    fn dense(problem: &BeamProblem, values: &[f64]) -> DMatrix<f64> {
        let mut m = DMatrix::zeros(problem.dim(), problem.dim());
        for (&(r, c), &v) in problem.step_pattern().iter().zip(values) {
            m[(r, c)] += v;
        }
        m
    }

    fn values(problem: &BeamProblem, kin: &Kinematics, old: &[f64], new: &[f64]) -> Vec<f64> {
        let input =
            StepInput { time: 0.2, dt: 0.05, loads: &problem.loads, node_quaternions: &kin.xi };
        let nnz = problem.beam.jacobian_nnz();
        let mut values = vec![1.0; nnz + 2 * problem.beam.k()];
        problem.beam.jacobian_values(&input, old, new, &mut values[..nnz]).unwrap();
        values
    }

    /// Block and sparse factorisations solve the step system alike (dense LU as reference).
    #[test]
    fn block_solve_matches_dense_solve() {
        for (i, (left, right)) in ends().into_iter().enumerate() {
            for components in [Components::Planar, Components::Spatial] {
                let (problem, kin, old, new) =
                    setup(50 + i as u64, components, left.clone(), right.clone());
                let values = values(&problem, &kin, &old, &new);
                let mut rng = seeded(7);
                let rhs = random_vec(&mut rng, problem.dim());
                let want =
                    dense(&problem, &values).lu().solve(&DVector::from_vec(rhs.clone())).unwrap();
                for choice in [LinearSolver::Auto, LinearSolver::SparseLu] {
                    let mut solver = StepSolver::new(&problem, choice).unwrap();
                    solver.factorize(&values).unwrap();
                    assert_eq!(solver.block_active, choice == LinearSolver::Auto);
                    let mut x = rhs.clone();
                    solver.solve(&mut x).unwrap();
                    let err = (DVector::from_vec(x) - &want).amax() / want.amax();
                    // random sections: condition ≲ 1e4, so the relative error stays ≲ 1e-11
                    assert!(err < 1e-10, "{components:?}, ends {i}, {choice:?}: {err}");
                }
            }
        }
    }

    /// Flux damping (`D2`) reaches two blocks away: the sparse LU is used from the start.
    #[test]
    fn flux_damping_uses_the_sparse_lu() {
        let section = samples::settling_damping(&samples::slender_section(), 1.0, 1e-3).unwrap();
        let beam = Beam::new(section, Mesh::uniform(1.0, 4).unwrap(), Components::Planar).unwrap();
        let problem =
            BeamProblem::new(beam, EndCondition::Clamped, EndCondition::Free, Loads::none())
                .unwrap();
        let solver = StepSolver::new(&problem, LinearSolver::Auto).unwrap();
        assert!(!solver.is_block());
        assert_eq!(solver.name(), "faer sparse LU");
    }

    /// A massless rotation at a free left end makes the first Schur block singular (at rest):
    /// the block LU refuses it and the sparse LU solves the system instead.
    #[test]
    fn singular_block_falls_back_to_the_sparse_lu() {
        let beam = Beam::new(
            samples::euler_bernoulli_section(),
            Mesh::uniform(1.0, 5).unwrap(),
            Components::Planar,
        )
        .unwrap();
        let problem =
            BeamProblem::new(beam, EndCondition::Free, EndCondition::Free, Loads::none()).unwrap();
        let kin = Kinematics::straight(&problem.beam);
        let zero = vec![0.0; problem.dim()];
        let values = values(&problem, &kin, &zero, &zero);
        let mut solver = StepSolver::new(&problem, LinearSolver::Auto).unwrap();
        assert!(solver.is_block());
        solver.factorize(&values).unwrap();
        assert_eq!(solver.block_refusals, 1);
        assert_eq!(solver.name(), "faer sparse LU");
        let rhs: Vec<f64> = (0..problem.dim()).map(|i| (i as f64 * 0.37).sin()).collect();
        let want = dense(&problem, &values).lu().solve(&DVector::from_vec(rhs.clone())).unwrap();
        let mut x = rhs;
        solver.solve(&mut x).unwrap();
        assert!((DVector::from_vec(x) - &want).amax() < 1e-10 * want.amax());
    }
}
