//! The lowest constrained modes of a large structure by shift-invert Lanczos on the sparse
//! pencil (`docs/theory.md §4`, eqs. 30–32), in memory and time linear in the mesh.
//!
//! The second-order problem of theory.md §4 (see [`crate::eigen`]) is
//!
//! ```text
//!   ω² B1 φ1 = K φ1,   K = D B2⁻¹ Dᵀ,   G1 φ1 = 0,   D_rᵀ φ1 = 0,   (K φ1)_massless = 0,
//! ```
//!
//! with `B1 = blkdiag(w_n M)`, `B2 = blkdiag(h_e C)` block diagonal, `D` banded and `G1` a few
//! joint and support rows. For a shift `σ < 0` the operator `S = (K − σB1)⁻¹ B1` on the
//! constrained space is `B1`-self-adjoint with eigenvalues `θ = 1/(ω² − σ)`: the lowest modes
//! (rigid ones, `ω = 0`, included: `θ = 1/|σ|`) are its largest eigenvalues. `S x` is one solve
//! of the sparse symmetric saddle-point system
//!
//! ```text
//!   [ −σB1   D    G1ᵀ ] [ y ]   [ B1 x ]
//!   [  Dᵀ   −B2   0   ] [ ψ ] = [  0   ]        (ψ = B2⁻¹Dᵀy on elastic rows; on rigid rows
//!   [  G1    0    0   ] [ μ ]   [  0   ]         of B2 it is the multiplier of D_rᵀ y = 0)
//! ```
//!
//! factorised once by sparse LU ([`intrinsic_beam::SparseLuSystem`], faer). Eliminating `ψ`
//! and `μ` gives `(K − σB1) y + G1ᵀμ = B1 x`, `G1 y = 0`, `D_rᵀ y = 0`: the constraints and the
//! rigid element rows are exact, and on massless rows `(K y)_massless = 0` is the static
//! condensation of the dense route, so every vector in the range of `S` is admissible. `K` is
//! never formed and nothing is squared.
//!
//! The eigenpairs of `S` come from [`crate::lanczos`] (full reorthogonalisation, fixed start
//! vector), run on each connected component of the sparsity graph of `B1`, `B2`, `D`, `G1`
//! separately, as the dense route does (a straight structure splits into its axial, torsion and
//! two bending families, whose spectra may coincide). The exact rigid rotations among the
//! candidates (`G1 c = 0`, `Dᵀ c = 0`) are the first rigid modes, as in the dense route, and
//! are deflated from the iteration. Then, for each returned pair:
//!
//! - `ω = ‖L2⁻¹ D_eᵀ φ1‖ / ‖φ1‖_B1` (`B2 = L2 L2ᵀ` by element blocks), the Rayleigh quotient
//!   without squaring the conditioning of `K`;
//! - the residual `r = ‖S φ1 − θ φ1‖_B1 / (|θ| ‖φ1‖_B1)` is recomputed with one more solve and
//!   must be at most `tolerance`: `S` is `B1`-self-adjoint, so an eigenvalue `θ*` lies within
//!   `r |θ|` of `θ`, i.e. `|ω*² − ω²| ≤ r (ω² − σ)` to first order;
//! - a mode is rigid when `ω² ≤ rigid_tolerance · λ_ref`, `λ_ref` a power-iteration estimate of
//!   the largest eigenvalue of the unconstrained pencil on its massive coordinates;
//! - `φ2 = B2⁻¹ Dᵀ φ1 / ω` (zero for rigid modes), and the sign makes the largest component of
//!   `φ1` positive, as in the dense route.
//!
//! **Shift.** `σ = −shift_fraction · λ_ref` first. When the lowest elastic eigenvalue found is
//! below `10 |σ|` (the wanted `θ` would crowd near `1/|σ|`) or the iteration did not converge,
//! the component is solved again with `σ = −0.01 ω₁²`, up to three times.

use crate::basis::{classify, BasisSettings};
use crate::blocks::BlockDiag;
use crate::eigen::{admissible_rigid_fields, canonical_rigid_basis_of, sign_of_largest, UnionFind};
use crate::error::{invalid, ModalError, Result};
use crate::lanczos::{self, Operator};
use crate::layout::Layout;
use crate::report::{report_from_parts, ModeReport};
use crate::sparse_problem::SparseProblem;
use crate::structure::{layout_of, rigid_candidates_of};
use faer::{Mat, MatRef};
use intrinsic_beam::SparseLuSystem;
use multibody_constraints::Structure;

mod operators;
use operators::{Csr, FactoredBlocks, MassRoot};

/// Settings of the sparse eigen route.
#[derive(Clone, Debug, PartialEq)]
pub struct SparseSettings {
    /// Relative residual `‖Sφ − θφ‖_B1 / |θ|` every returned pair must meet. Default `1e-10`;
    /// range `(0, 1e-4]`.
    pub tolerance: f64,
    /// Most Lanczos steps per connected component and shift. Default `400`; at least `10`.
    pub max_steps: usize,
    /// First shift `σ = −shift_fraction · λ_ref`. Default `1e-12` (the paper's sections have
    /// their first elastic `ω²` near `1e-7 λ_max` at 2 × 50 elements, falling as `N⁻²`);
    /// range `(0, 1e-3]`.
    pub shift_fraction: f64,
}

impl Default for SparseSettings {
    fn default() -> Self {
        SparseSettings { tolerance: 1e-10, max_steps: 400, shift_fraction: 1e-12 }
    }
}

impl SparseSettings {
    /// Checks the ranges documented on each field.
    pub fn validate(&self) -> Result<()> {
        if !(self.tolerance > 0.0 && self.tolerance <= 1e-4) {
            return Err(invalid("tolerance", self.tolerance, "must lie in (0, 1e-4]"));
        }
        if self.max_steps < 10 {
            return Err(invalid("max_steps", self.max_steps, "must be at least 10"));
        }
        if !(self.shift_fraction > 0.0 && self.shift_fraction <= 1e-3) {
            return Err(invalid("shift_fraction", self.shift_fraction, "must lie in (0, 1e-3]"));
        }
        Ok(())
    }
}

impl SparseProblem {
    /// The problem of a structure at its reference configuration, with its layout and the
    /// rigid rotations that fix the rigid-mode basis (as [`crate::StructureModel`], without
    /// any dense matrix).
    pub fn of_structure(structure: &Structure) -> Result<(Layout, SparseProblem, Mat<f64>)> {
        let layout = layout_of(structure)?;
        let (b, a, _) = structure.linear_operators();
        let g = structure.constraint_matrix();
        let p = SparseProblem::from_full_entries(&layout, b, a, g.rows, g.entries)?;
        let candidates = rigid_candidates_of(structure, &layout)?;
        Ok((layout, p, candidates))
    }
}

/// The lowest modes from the sparse route: rigid first, then elastic by frequency.
#[derive(Clone, Debug)]
pub struct SparseModes {
    /// Eigenvalues `ω²` (rigid ones as computed, round-off).
    pub lambda: Vec<f64>,
    /// Frequencies `ω ≥ 0` (exactly 0 for rigid modes).
    pub omega: Vec<f64>,
    /// Velocity modes (n1 × m), `B1`-orthonormal.
    pub phi1: Mat<f64>,
    /// Force modes (n2 × m), `φ2 = B2⁻¹Dᵀφ1/ω`, zero for rigid modes.
    pub phi2: Mat<f64>,
    /// Rigid modes among the returned ones (the first columns).
    pub n_rigid: usize,
    /// Relative residual `‖Sφ − θφ‖_B1 / |θ|` of each mode (0 for the exact rigid rotations).
    pub residuals: Vec<f64>,
    /// `λ_ref`, the estimate of the largest eigenvalue the rigid test is relative to.
    pub lambda_ref: f64,
    /// Per connected component: `(X1 unknowns, Lanczos steps, last shift σ)`.
    pub components: Vec<(usize, usize, f64)>,
}

/// Shift-inverted operator of one component: one saddle-point solve per application.
struct ShiftInvert {
    lu: SparseLuSystem,
    /// The saddle-point matrix itself, for the refinement step.
    kkt: Csr,
    b1: Csr,
    rhs: Vec<f64>,
    work: Vec<f64>,
}

impl Operator for ShiftInvert {
    fn n(&self) -> usize {
        self.b1.nrows()
    }
    fn apply(&mut self, x: &[f64], y: &mut [f64]) -> Result<()> {
        let n = self.n();
        self.rhs.iter_mut().for_each(|v| *v = 0.0);
        self.b1.matvec(x, &mut self.rhs[..n]);
        let b = self.rhs.clone();
        let fail = |e: intrinsic_beam::BeamError| ModalError::Numerical {
            stage: "sparse shift-invert solve of the modal saddle-point system".into(),
            reason: format!("{e} (dependent joint or support rows, or a massless mechanism)"),
        };
        self.lu.solve(&mut self.rhs).map_err(fail)?;
        // one step of iterative refinement: r = b − A y, y += A⁻¹ r
        self.kkt.matvec(&self.rhs, &mut self.work);
        self.work.iter_mut().zip(&b).for_each(|(w, b)| *w = b - *w);
        self.lu.solve(&mut self.work).map_err(fail)?;
        self.rhs.iter_mut().zip(&self.work).for_each(|(y, d)| *y += d);
        y.copy_from_slice(&self.rhs[..n]);
        Ok(())
    }
    fn inner(&self, x: &[f64], y: &mut [f64]) {
        y.iter_mut().for_each(|v| *v = 0.0);
        self.b1.matvec(x, y);
    }
}

/// One connected component: its `X1` and `X2` unknowns and `G1` rows (global indices).
struct Component {
    s1: Vec<usize>,
    s2: Vec<usize>,
    rows: Vec<usize>,
}

fn components(p: &SparseProblem) -> Vec<Component> {
    let (n1, n2) = (p.n1, p.n2);
    let mut uf = UnionFind((0..n1 + n2).collect());
    for &(i, j, v) in &p.b1 {
        if v != 0.0 {
            uf.union(i, j);
        }
    }
    for &(i, j, v) in &p.b2 {
        if v != 0.0 {
            uf.union(n1 + i, n1 + j);
        }
    }
    for &(i, e, v) in &p.d {
        if v != 0.0 {
            uf.union(i, n1 + e);
        }
    }
    let mut first = vec![usize::MAX; p.g_rows];
    for &(r, q, v) in &p.g1 {
        if v != 0.0 {
            if first[r] == usize::MAX {
                first[r] = q;
            } else {
                uf.union(first[r], q);
            }
        }
    }
    let mut index = std::collections::HashMap::new();
    let mut out: Vec<Component> = Vec::new();
    for i in 0..n1 + n2 {
        let r = uf.find(i);
        let c = *index.entry(r).or_insert_with(|| {
            out.push(Component { s1: vec![], s2: vec![], rows: vec![] });
            out.len() - 1
        });
        if i < n1 {
            out[c].s1.push(i);
        } else {
            out[c].s2.push(i - n1);
        }
    }
    for (r, &q) in first.iter().enumerate() {
        if q != usize::MAX {
            let c = index[&uf.find(q)];
            out[c].rows.push(r);
        }
    }
    out.retain(|c| !c.s1.is_empty());
    out
}

/// Builds and factorises the saddle-point matrix of component `c` at shift `σ`.
fn shift_invert(p: &SparseProblem, c: &Component, sigma: f64) -> Result<ShiftInvert> {
    let (m1, m2, mc) = (c.s1.len(), c.s2.len(), c.rows.len());
    let local = |s: &[usize], n: usize| {
        let mut map = vec![usize::MAX; n];
        s.iter().enumerate().for_each(|(l, &g)| map[g] = l);
        map
    };
    let (l1, l2, lr) = (local(&c.s1, p.n1), local(&c.s2, p.n2), local(&c.rows, p.g_rows));
    let mut b1 = Vec::new();
    let (mut pattern, mut values) = (Vec::new(), Vec::new());
    let mut push = |r: usize, q: usize, v: f64| {
        pattern.push((r, q));
        values.push(v);
    };
    for &(i, j, v) in &p.b1 {
        if l1[i] != usize::MAX {
            b1.push((l1[i], l1[j], v));
            push(l1[i], l1[j], -sigma * v);
        }
    }
    for &(i, e, v) in &p.d {
        if l1[i] != usize::MAX {
            push(l1[i], m1 + l2[e], v);
            push(m1 + l2[e], l1[i], v);
        }
    }
    for &(i, j, v) in &p.b2 {
        if l2[i] != usize::MAX {
            push(m1 + l2[i], m1 + l2[j], -v);
        }
    }
    for &(r, q, v) in &p.g1 {
        if lr[r] != usize::MAX {
            push(m1 + m2 + lr[r], l1[q], v);
            push(l1[q], m1 + m2 + lr[r], v);
        }
    }
    let n = m1 + m2 + mc;
    let mut lu = SparseLuSystem::new(n, &pattern)?;
    lu.factorize(&values).map_err(|e| ModalError::Numerical {
        stage: "sparse LU of the modal saddle-point system".into(),
        reason: e.to_string(),
    })?;
    let entries: Vec<(usize, usize, f64)> =
        pattern.iter().zip(&values).map(|(&(r, c), &v)| (r, c, v)).collect();
    Ok(ShiftInvert {
        lu,
        kkt: Csr::new(n, n, &entries),
        b1: Csr::new(m1, m1, &b1),
        rhs: vec![0.0; n],
        work: vec![0.0; n],
    })
}

/// A Ritz pair of one component in global coordinates.
struct Pair {
    lambda: f64,
    phi1: Vec<f64>,
    residual: f64,
}

/// What [`solve_component`] returns: the pairs, Lanczos steps, whether they converged, and
/// the exact rigid fields restricted to the component (deflated, global coordinates).
struct ComponentSolution {
    pairs: Vec<Pair>,
    steps: usize,
    converged: bool,
    restricted: Vec<Vec<f64>>,
}

/// Solves component `c` at shift `σ`: up to `nev` pairs, with their global `φ1`, Rayleigh
/// quotient `ω²` and true residual.
fn solve_component(
    p: &SparseProblem,
    c: &Component,
    ops: &GlobalOps,
    exact: &[(Vec<f64>, Vec<f64>)],
    sigma: f64,
    nev: usize,
    settings: &SparseSettings,
) -> Result<ComponentSolution> {
    let mut op = shift_invert(p, c, sigma)?;
    // the exact rigid fields restricted to the component, B1-orthonormalised
    let mut deflate: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    let mut bq = vec![0.0; c.s1.len()];
    for (q, _) in exact {
        let mut v: Vec<f64> = c.s1.iter().map(|&g| q[g]).collect();
        op.inner(&v, &mut bq);
        let n0 = lanczos_dot(&v, &bq).max(0.0).sqrt();
        if n0 == 0.0 {
            continue;
        }
        for _ in 0..2 {
            for (d, bd) in &deflate {
                let a = lanczos_dot(bd, &v);
                v.iter_mut().zip(d).for_each(|(x, y)| *x -= a * y);
            }
        }
        op.inner(&v, &mut bq);
        let n = lanczos_dot(&v, &bq).max(0.0).sqrt();
        if n > 1e-6 * n0 {
            deflate.push((v.iter().map(|x| x / n).collect(), bq.iter().map(|x| x / n).collect()));
        }
    }
    let ritz =
        lanczos::largest(&mut op, &deflate, nev, 0.1 * settings.tolerance, settings.max_steps)?;
    let mut pairs = Vec::new();
    let mut y = vec![0.0; c.s1.len()];
    for (theta, x) in ritz.theta.iter().zip(&ritz.vectors) {
        op.apply(x, &mut y)?;
        let mut r: Vec<f64> = y.iter().zip(x).map(|(a, b)| a - theta * b).collect();
        for (d, bd) in &deflate {
            let a = lanczos_dot(bd, &r);
            r.iter_mut().zip(d).for_each(|(x, y)| *x -= a * y);
        }
        op.inner(&r, &mut bq);
        let residual = lanczos_dot(&r, &bq).max(0.0).sqrt() / theta.abs();
        let mut phi1 = vec![0.0; p.n1];
        c.s1.iter().zip(x).for_each(|(&g, &v)| phi1[g] = v);
        let lambda = ops.rayleigh(&phi1);
        pairs.push(Pair { lambda, phi1, residual });
    }
    let restricted = deflate
        .iter()
        .map(|(q, _)| {
            let mut v = vec![0.0; p.n1];
            c.s1.iter().zip(q).for_each(|(&g, &x)| v[g] = x);
            v
        })
        .collect();
    Ok(ComponentSolution { pairs, steps: ritz.steps, converged: ritz.converged, restricted })
}

fn lanczos_dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Global operators: `B1`, `B2` by blocks (factored), `D`, `G1`.
struct GlobalOps {
    b1: BlockDiag,
    f1: MassRoot,
    l2: FactoredBlocks,
    d: Csr,
    g: Csr,
}

impl GlobalOps {
    fn new(p: &SparseProblem, k: usize, rank_tolerance: f64) -> Result<Self> {
        let b1 = BlockDiag::from_entries("B1", p.n1, k, &p.b1)?;
        let b2 = BlockDiag::from_entries("B2", p.n2, k, &p.b2)?;
        let f1 = MassRoot::new(&b1, rank_tolerance);
        let l2 = FactoredBlocks::compliance("B2", &b2)?;
        Ok(GlobalOps {
            b1,
            f1,
            l2,
            d: Csr::new(p.n1, p.n2, &p.d),
            g: Csr::new(p.g_rows, p.n1, &p.g1),
        })
    }

    /// `ω² = ‖L2⁻¹ D_eᵀ φ1‖² / ‖φ1‖²_B1`.
    fn rayleigh(&self, phi1: &[f64]) -> f64 {
        let mut y = vec![0.0; self.d.ncols()];
        self.d.tmatvec(phi1, &mut y);
        self.l2.lower_solve(&mut y);
        let num: f64 = y.iter().map(|v| v * v).sum();
        let b = self.b1.apply_vec(phi1);
        num / lanczos_dot(phi1, &b)
    }

    /// Power-iteration estimate of the largest eigenvalue of `B1⁺ D B2⁻¹ Dᵀ` on the massive
    /// coordinates (unconstrained), 40 iterations from the fixed start vector.
    fn lambda_ref(&self) -> f64 {
        let n1 = self.d.nrows();
        let mut x = lanczos::start_vector(n1, 7);
        let mut est = 0.0;
        for _ in 0..40 {
            let nx = x.iter().map(|v| v * v).sum::<f64>().sqrt();
            if nx == 0.0 {
                return est;
            }
            x.iter_mut().for_each(|v| *v /= nx);
            let mut u = x.clone();
            self.f1.apply(&mut u);
            let mut y = vec![0.0; self.d.ncols()];
            self.d.tmatvec(&u, &mut y);
            self.l2.lower_solve(&mut y);
            est = y.iter().map(|v| v * v).sum::<f64>();
            self.l2.upper_solve(&mut y);
            let mut z = vec![0.0; n1];
            self.d.matvec(&y, &mut z);
            self.f1.apply(&mut z);
            x = z;
        }
        est
    }
}

/// The `n_modes` lowest constrained modes of `problem` (fewer if the structure has fewer), by
/// the sparse route of the module docs; `rigid_candidates` as in [`crate::solve_second_order`].
pub fn solve_sparse(
    problem: &SparseProblem,
    k: usize,
    n_modes: usize,
    basis: &BasisSettings,
    settings: &SparseSettings,
    rigid_candidates: Option<MatRef<'_, f64>>,
) -> Result<SparseModes> {
    basis.validate()?;
    settings.validate()?;
    if n_modes == 0 {
        return Err(invalid("n_modes", n_modes, "must be at least 1"));
    }
    let n1 = problem.n1;
    let ops = GlobalOps::new(problem, k, basis.eigen.rank_tolerance)?;
    for (what, e) in
        [("B1", &problem.b1), ("B2", &problem.b2), ("D", &problem.d), ("G1", &problem.g1)]
    {
        if let Some(i) = e.iter().position(|x| !x.2.is_finite()) {
            return Err(ModalError::NonFinite { what: what.into(), index: i });
        }
    }
    let exact = match rigid_candidates {
        None => Vec::new(),
        Some(c) => {
            if c.nrows() != n1 {
                return Err(crate::error::shape(
                    "rigid_candidates",
                    (n1, c.ncols()),
                    (c.nrows(), c.ncols()),
                ));
            }
            let apply = |f: &dyn Fn(&[f64], &mut [f64]), rows: usize| {
                let mut out = Mat::<f64>::zeros(rows, c.ncols());
                for j in 0..c.ncols() {
                    let x: Vec<f64> = (0..n1).map(|i| c[(i, j)]).collect();
                    let mut y = vec![0.0; rows];
                    f(&x, &mut y);
                    (0..rows).for_each(|i| out[(i, j)] = y[i]);
                }
                out
            };
            let gres = apply(&|x, y| ops.g.matvec(x, y), problem.g_rows);
            let dres = apply(&|x, y| ops.d.tmatvec(x, y), problem.n2);
            let bc = apply(&|x, y| y.copy_from_slice(&ops.b1.apply_vec(x)), n1);
            let (gmax, dmax) = (ops.g.max_abs(), ops.d.max_abs());
            admissible_rigid_fields(c, gres.as_ref(), dres.as_ref(), bc.as_ref(), gmax, dmax)
        }
    };
    let lambda_ref = ops.lambda_ref();
    let rigid_threshold = basis.eigen.rigid_tolerance * lambda_ref;
    let mut elastic: Vec<(f64, usize, usize, Pair)> = Vec::new();
    let mut rigid_found: Vec<Pair> = Vec::new();
    let mut comp_info = Vec::new();
    for (ci, c) in components(problem).iter().enumerate() {
        let nev = (n_modes + 1).min(c.s1.len());
        let mut sigma = -settings.shift_fraction * lambda_ref;
        let mut steps = 0;
        let mut result = None;
        let mut deflated = Vec::new();
        for _pass in 0..3 {
            let ComponentSolution { pairs, steps: s, converged, restricted } =
                solve_component(problem, c, &ops, &exact, sigma, nev, settings)?;
            deflated = restricted;
            steps += s;
            let low = pairs
                .iter()
                .map(|p| p.lambda)
                .filter(|&l| l > rigid_threshold)
                .fold(f64::INFINITY, f64::min);
            let crowded = low.is_finite() && low < 10.0 * sigma.abs();
            let bad = pairs.iter().any(|p| p.residual.is_nan() || p.residual > settings.tolerance);
            result = Some((pairs, converged && !bad));
            if !(crowded || !converged || bad) || !low.is_finite() {
                break;
            }
            sigma = -0.01 * low;
        }
        let Some((pairs, ok)) = result else { continue };
        if !ok {
            let worst = pairs.iter().map(|p| p.residual).fold(0.0f64, f64::max);
            return Err(ModalError::Numerical {
                stage: "sparse Lanczos iteration of the constrained modes".into(),
                reason: format!(
                    "component {ci} ({} node unknowns) did not converge in {} steps: worst \
                     relative residual {worst:.2e} above the tolerance {:.0e} (raise max_steps)",
                    c.s1.len(),
                    settings.max_steps,
                    settings.tolerance
                ),
            });
        }
        comp_info.push((c.s1.len(), steps, sigma));
        for v in deflated {
            rigid_found.push(Pair { lambda: ops.rayleigh(&v), phi1: v, residual: 0.0 });
        }
        for (j, pair) in pairs.into_iter().enumerate() {
            if pair.lambda <= rigid_threshold {
                rigid_found.push(pair);
            } else {
                elastic.push((pair.lambda, ci, j, pair));
            }
        }
    }
    elastic.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    // Rigid modes: the exact rotations, then a canonical basis of the other rigid directions
    // (restrictions of the rotations to a component that are not combinations of them, and
    // the rigid pairs the iteration found).
    let mut extra: Vec<Vec<f64>> = Vec::new();
    let mut extra_b: Vec<Vec<f64>> = Vec::new();
    let mut residual_of_extra = Vec::new();
    for pair in &rigid_found {
        let mut v = pair.phi1.clone();
        let n0 = lanczos_dot(&v, &ops.b1.apply_vec(&v)).max(0.0).sqrt();
        for _ in 0..2 {
            for (q, bq) in exact.iter().map(|(a, b)| (a, b)).chain(extra.iter().zip(&extra_b)) {
                let a = lanczos_dot(bq, &v);
                v.iter_mut().zip(q).for_each(|(x, y)| *x -= a * y);
            }
        }
        let bv = ops.b1.apply_vec(&v);
        let n = lanczos_dot(&v, &bv).max(0.0).sqrt();
        if n > 1e-6 * n0 {
            extra.push(v.iter().map(|x| x / n).collect());
            extra_b.push(bv.iter().map(|x| x / n).collect());
            residual_of_extra.push(pair.residual);
        }
    }
    let n_rigid = exact.len() + extra.len();
    let m = n_modes.min(n_rigid + elastic.len());
    let mut phi1 = Mat::<f64>::zeros(n1, m);
    let mut phi2 = Mat::<f64>::zeros(problem.n2, m);
    let (mut lambda, mut omega, mut residuals) = (vec![0.0; m], vec![0.0; m], vec![0.0; m]);
    for (j, (v, _)) in exact.iter().enumerate().take(m) {
        (0..n1).for_each(|i| phi1[(i, j)] = v[i]);
        lambda[j] = ops.rayleigh(v);
    }
    if !extra.is_empty() {
        let r = Mat::from_fn(n1, extra.len(), |i, j| extra[j][i]);
        let br = Mat::from_fn(n1, extra.len(), |i, j| extra_b[j][i]);
        let canonical = canonical_rigid_basis_of(&br, &r)?;
        for j in 0..extra.len() {
            let col = exact.len() + j;
            if col < m {
                (0..n1).for_each(|i| phi1[(i, col)] = canonical[(i, j)]);
                let v: Vec<f64> = (0..n1).map(|i| canonical[(i, j)]).collect();
                lambda[col] = ops.rayleigh(&v);
                residuals[col] = residual_of_extra[j];
            }
        }
    }
    for (e, (l, _, _, pair)) in elastic.iter().enumerate() {
        let col = n_rigid + e;
        if col >= m {
            break;
        }
        let w = l.sqrt();
        let sign = sign_of_largest(&pair.phi1);
        let nrm = lanczos_dot(&pair.phi1, &ops.b1.apply_vec(&pair.phi1)).sqrt();
        let v: Vec<f64> = pair.phi1.iter().map(|x| sign * x / nrm).collect();
        let mut y = vec![0.0; problem.n2];
        ops.d.tmatvec(&v, &mut y);
        ops.l2.lower_solve(&mut y);
        ops.l2.upper_solve(&mut y);
        (0..n1).for_each(|i| phi1[(i, col)] = v[i]);
        (0..problem.n2).for_each(|i| phi2[(i, col)] = y[i] / w);
        lambda[col] = *l;
        omega[col] = w;
        residuals[col] = pair.residual;
    }
    Ok(SparseModes {
        lambda,
        omega,
        phi1,
        phi2,
        n_rigid,
        residuals,
        lambda_ref,
        components: comp_info,
    })
}

/// The first `n_modes` constrained modes of `structure` (fewer if it has fewer) by the sparse
/// route, labelled as [`crate::ModalBasis`] labels them: the same report as
/// [`crate::mode_report`], in memory and time linear in the mesh.
pub fn sparse_mode_report(
    structure: &Structure,
    n_modes: usize,
    basis: &BasisSettings,
    settings: &SparseSettings,
) -> Result<ModeReport> {
    let (layout, problem, candidates) = SparseProblem::of_structure(structure)?;
    let k = layout.k();
    let modes = solve_sparse(&problem, k, n_modes, basis, settings, Some(candidates.as_ref()))?;
    let b1 = BlockDiag::from_entries("B1", problem.n1, k, &problem.b1)?;
    let b2 = BlockDiag::from_entries("B2", problem.n2, k, &problem.b2)?;
    let b1p = b1.apply(modes.phi1.as_ref());
    let b2p = b2.apply(modes.phi2.as_ref());
    let labels: Vec<String> = (0..modes.omega.len())
        .map(|j| {
            let kinetic = (0..problem.n1).map(|i| modes.phi1[(i, j)] * b1p[(i, j)]);
            let strain = (0..problem.n2).map(|i| modes.phi2[(i, j)] * b2p[(i, j)]);
            let (kind, _) = classify(
                layout.components,
                j < modes.n_rigid,
                basis.label_threshold,
                kinetic,
                strain,
            );
            kind.label(layout.components).to_string()
        })
        .collect();
    let n_rigid = modes.n_rigid;
    Ok(report_from_parts(&layout, &modes.omega, &labels, n_rigid, |j, b, n| {
        let i0 = layout.x1_index(b, n, 0);
        (0..k).map(|c| modes.phi1[(i0 + c, j)]).collect()
    }))
}
