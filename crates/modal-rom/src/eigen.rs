//! Constrained linear modes by second-order reduction (theory.md §4; paper eqs. 30–32).
//!
//! The linearised, undamped FE model at rest is `B Ẋ = A X`, `G X = 0` (31). Split into node
//! values `X1` and element values `X2`, it reads
//!
//! ```text
//!   B1 Ẋ1 =  D X2          (node rows:    w_n M ẋ1_n = x2 differences + h/2 E x2)
//!   B2 Ẋ2 = −Dᵀ X1         (element rows: h_e C ẋ2_e = x1 differences − h Eᵀ x̄1)
//!   G1 X1 = 0              (velocity rows of supports and joints, eq. 11)
//! ```
//!
//! with the end values `x2_L/R` (reactions, eq. 12) dropping out: on velocities that satisfy
//! `G1`, the reactions do no work (joints are power-free, theory.md §3). Eliminating `X2` where
//! `B2` is invertible gives the symmetric definite problem
//!
//! ```text
//!   ω² B1 φ1 = K φ1,   K = D B2⁻¹ Dᵀ,   φ1 ∈ null(G1) ∩ null(D_rᵀ) (rigid C rows),
//! ```
//!
//! and massless rows (`B1 = 0`) add the constraint `(K φ1)_massless = 0`. All constraints are
//! absorbed into a null-space basis `Z` (32): the velocity and rigid rows by an SVD, the
//! massless directions (null space of `F Z`, `FᵀF = B1`, decided on singular values) by static
//! condensation, a least-squares solve on the strain map `L2⁻¹DᵀZ` (see `condense_massless`).
//! With `ZᵀB1Z = L1 L1ᵀ` and `B2 = L2 L2ᵀ` (Cholesky; for a block with massless coordinates,
//! `L1ᵀ` is the QR factor of `F Z`), `L1⁻¹ ZᵀKZ L1⁻ᵀ = MᵀM` with `M = L2⁻¹ Dᵀ Z L1⁻ᵀ`, so the frequencies are the
//! singular values of `M` (faer SVD): `M v = ω u`, `φ1 = Z L1⁻ᵀ v`, `φ2 = L2⁻ᵀ u`. Working
//! with `M` instead of `K` avoids squaring its condition number (shear stiffness over h²,
//! rotary inertia 1e-5: cond(K) ≈ 1e8–1e10 for the paper's scenes): `φ1` is `B1`-orthonormal
//! and `φ2` `B2`-orthonormal to round-off, and `⟨φ1i, Dφ2j⟩ = ω_j δij` to round-off.
//!
//! **Force modes and sign.** `φ2 = +B2⁻¹ Dᵀ φ1 / ω` (elastic modes; rigid modes have
//! `φ2 ≡ 0`). With this choice `⟨φ1i, D φ2j⟩ = +ω_j δij` and the modal equations are the
//! paper's (15): `q̇1 = Ω q2`, `q̇2 = −Ω q1`.
//!
//! **Decoupling.** The problem is split into the connected components of the sparsity graph
//! of `B1`, `B2`, `D`, `G1` (e.g. axial, torsion and the two bending families of a straight
//! structure at 0°) and each block is solved on its own: exact, and much faster.

use crate::error::{invalid, shape, ModalError, Result};
use crate::layout::Layout;
use crate::sparse_problem::SparseProblem;
use faer::{Mat, MatRef, Side};

/// Settings of the constrained eigen solver.
#[derive(Clone, Debug, PartialEq)]
pub struct EigenSettings {
    /// An eigenvalue `ω²` is a rigid-body mode when `ω² ≤ rigid_tolerance · max ω²`.
    /// Default `1e-24`, i.e. `ω ≤ 1e-12 ω_max`. The frequencies are singular values (SVD
    /// route), so a rigid mode comes out at round-off `ω ≈ 1e-16 ω_max` (measured
    /// `ω² ≤ 5e-32 max ω²`, free–free beams up to 400 elements). The lowest elastic mode sits
    /// near `1e-7 · max ω²` for the paper's sections at any mesh, but an Euler–Bernoulli
    /// section (rigid shear, massless rotation) has `max ω² ∝ N⁶` (slaved node rotations) and
    /// its first bending mode near `0.5 N⁻⁶ · max ω²` (clamped) or `77 N⁻⁶` (free–free):
    /// a looser tolerance such as `1e-10` turns its low bending modes into "rigid" ones from
    /// about 42 elements on. `1e-24` holds to about 9000 elements. Range `(0, 1e-4]`.
    pub rigid_tolerance: f64,
    /// Relative singular-value cut-off for constraint rank and massless directions (singular
    /// values of `F Z`, `FᵀF = B1`: an Euler–Bernoulli section's clamped slaved rotations reach
    /// `≈ 0.74/N²`, exact massless directions round-off). Default `1e-10`. Range `(0, 1e-3]`.
    pub rank_tolerance: f64,
}

impl Default for EigenSettings {
    fn default() -> Self {
        EigenSettings { rigid_tolerance: 1e-24, rank_tolerance: 1e-10 }
    }
}

impl EigenSettings {
    /// Checks the ranges documented on each field.
    pub fn validate(&self) -> Result<()> {
        if !(self.rigid_tolerance > 0.0 && self.rigid_tolerance <= 1e-4) {
            return Err(invalid("rigid_tolerance", self.rigid_tolerance, "must lie in (0, 1e-4]"));
        }
        if !(self.rank_tolerance > 0.0 && self.rank_tolerance <= 1e-3) {
            return Err(invalid("rank_tolerance", self.rank_tolerance, "must lie in (0, 1e-3]"));
        }
        Ok(())
    }
}

/// The linearised FE operators in second-order form (see the module docs).
#[derive(Clone, Debug)]
pub struct SecondOrderProblem {
    /// `B1` (n1 × n1): node mass blocks `w_n M`, symmetric positive semidefinite.
    pub b1: Mat<f64>,
    /// `B2` (n2 × n2): element compliance blocks `h_e C`, symmetric positive semidefinite.
    pub b2: Mat<f64>,
    /// `D` (n1 × n2): node rows, element columns of the skew operator `A`.
    pub d: Mat<f64>,
    /// `G1` (c × n1): velocity constraint rows (supports, joints, prescribed motion).
    pub g: Mat<f64>,
}

fn check_finite(what: &str, m: MatRef<'_, f64>) -> Result<()> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            if !m[(i, j)].is_finite() {
                return Err(ModalError::NonFinite {
                    what: what.to_string(),
                    index: j * m.nrows() + i,
                });
            }
        }
    }
    Ok(())
}

impl SecondOrderProblem {
    /// Builds the problem from its blocks, checking shapes, finiteness and symmetry of `B1`, `B2`.
    pub fn new(b1: Mat<f64>, b2: Mat<f64>, d: Mat<f64>, g: Mat<f64>) -> Result<Self> {
        let (n1, n2) = (b1.nrows(), b2.nrows());
        if b1.ncols() != n1 {
            return Err(shape("B1", (n1, n1), (b1.nrows(), b1.ncols())));
        }
        if b2.ncols() != n2 {
            return Err(shape("B2", (n2, n2), (b2.nrows(), b2.ncols())));
        }
        if d.nrows() != n1 || d.ncols() != n2 {
            return Err(shape("D", (n1, n2), (d.nrows(), d.ncols())));
        }
        if g.ncols() != n1 {
            return Err(shape("G1", (g.nrows(), n1), (g.nrows(), g.ncols())));
        }
        for (what, m) in
            [("B1", b1.as_ref()), ("B2", b2.as_ref()), ("D", d.as_ref()), ("G1", g.as_ref())]
        {
            check_finite(what, m)?;
        }
        for (what, m) in [("B1", b1.as_ref()), ("B2", b2.as_ref())] {
            let scale = max_abs(m).max(f64::MIN_POSITIVE);
            for j in 0..m.ncols() {
                for i in 0..j {
                    if (m[(i, j)] - m[(j, i)]).abs() > 1e-12 * scale {
                        return Err(invalid(
                            format!("{what}[({i}, {j})]"),
                            m[(i, j)],
                            format!("{what} must be symmetric"),
                        ));
                    }
                }
                if m[(j, j)] < 0.0 {
                    return Err(invalid(
                        format!("{what}[({j}, {j})]"),
                        m[(j, j)],
                        "diagonal must be ≥ 0",
                    ));
                }
            }
        }
        Ok(SecondOrderProblem { b1, b2, d, g })
    }

    /// Builds the problem from the full FE operators in the ordering of theory.md §2, given as
    /// `(row, col, value)` entries (duplicates are summed): `B` (n_full²), the skew `A`
    /// (n_full²) and `G` (`g_rows × n_full`).
    ///
    /// Rows of `G` on end values only (free-end and force-balance rows) close the reactions
    /// and are not needed for the modes; rows on node values only are the velocity
    /// constraints `G1`; a row on element values, or mixing node and end values, is rejected.
    /// The element-row block of `A` must equal `−Dᵀ` (skew), to `1e-12` relative.
    pub fn from_full_entries(
        layout: &Layout,
        b: impl IntoIterator<Item = (usize, usize, f64)>,
        a: impl IntoIterator<Item = (usize, usize, f64)>,
        g_rows: usize,
        g: impl IntoIterator<Item = (usize, usize, f64)>,
    ) -> Result<Self> {
        SparseProblem::from_full_entries(layout, b, a, g_rows, g)?.to_dense()
    }

    /// `n1`, the length of `X1`.
    pub fn n1(&self) -> usize {
        self.b1.nrows()
    }

    /// `n2`, the length of `X2`.
    pub fn n2(&self) -> usize {
        self.b2.nrows()
    }
}

impl SparseProblem {
    /// The dense problem (entries summed in order), checked by [`SecondOrderProblem::new`].
    pub fn to_dense(&self) -> Result<SecondOrderProblem> {
        let dense = |r: usize, c: usize, e: &[(usize, usize, f64)]| {
            let mut m = Mat::<f64>::zeros(r, c);
            for &(i, j, v) in e {
                m[(i, j)] += v;
            }
            m
        };
        SecondOrderProblem::new(
            dense(self.n1, self.n1, &self.b1),
            dense(self.n2, self.n2, &self.b2),
            dense(self.n1, self.n2, &self.d),
            dense(self.g_rows, self.n1, &self.g1),
        )
    }
}

/// Modes as computed: rigid first (in the canonical basis), then elastic by frequency.
#[derive(Clone, Debug)]
pub struct RawModes {
    /// Eigenvalues `ω²` as computed (rigid ones may be ±round-off).
    pub lambda: Vec<f64>,
    /// Frequencies `ω ≥ 0` (exactly 0 for rigid modes).
    pub omega: Vec<f64>,
    /// Velocity modes (n1 × m), `B1`-orthonormal.
    pub phi1: Mat<f64>,
    /// Force modes (n2 × m), `φ2 = B2⁻¹Dᵀφ1/ω` (zero for rigid modes).
    pub phi2: Mat<f64>,
    /// Number of rigid-body modes (the first columns).
    pub n_rigid: usize,
    /// Largest eigenvalue `max ω²` (conditioning reference).
    pub lambda_max: f64,
    /// Sizes of the decoupled blocks solved (in `X1` unknowns after reduction).
    pub block_sizes: Vec<usize>,
}

pub(crate) fn max_abs(m: MatRef<'_, f64>) -> f64 {
    let mut out = 0.0f64;
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            out = out.max(m[(i, j)].abs());
        }
    }
    out
}

fn gather(m: MatRef<'_, f64>, rows: &[usize], cols: &[usize]) -> Mat<f64> {
    Mat::from_fn(rows.len(), cols.len(), |i, j| m[(rows[i], cols[j])])
}

fn symmetrize(m: &mut Mat<f64>) {
    let n = m.nrows();
    for j in 0..n {
        for i in 0..j {
            let s = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = s;
            m[(j, i)] = s;
        }
    }
}

pub(crate) struct UnionFind(pub(crate) Vec<usize>);

impl UnionFind {
    pub(crate) fn find(&mut self, mut a: usize) -> usize {
        while self.0[a] != a {
            self.0[a] = self.0[self.0[a]];
            a = self.0[a];
        }
        a
    }
    pub(crate) fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
            self.0[hi] = lo;
        }
    }
}

/// `F` with `FᵀF = B1` (rows: the massive directions of `B1`): `diag(√b_ii)` rows for a
/// diagonal `B1` (exact), else `Λ^½Uᵀ` from its eigen decomposition, dropping eigenvalues
/// `≤ tol · λ_max` (its own null space).
fn mass_factor(b1: &Mat<f64>, tol: f64) -> Result<Mat<f64>> {
    let n = b1.nrows();
    let diagonal = (0..n).all(|j| (0..n).all(|i| i == j || b1[(i, j)] == 0.0));
    if diagonal {
        let rows: Vec<usize> = (0..n).filter(|&i| b1[(i, i)] > 0.0).collect();
        let mut f = Mat::<f64>::zeros(rows.len(), n);
        for (r, &i) in rows.iter().enumerate() {
            f[(r, i)] = b1[(i, i)].sqrt();
        }
        return Ok(f);
    }
    let eig = b1.self_adjoint_eigen(Side::Lower).map_err(|e| ModalError::Numerical {
        stage: "eigen of the mass block B1".into(),
        reason: format!("{e:?}"),
    })?;
    let s = eig.S().column_vector();
    let smax = (0..n).map(|i| s[i]).fold(0.0f64, f64::max);
    let keep: Vec<usize> = (0..n).filter(|&i| s[i] > tol * smax).collect();
    let u = eig.U();
    Ok(Mat::from_fn(keep.len(), n, |r, j| s[keep[r]].sqrt() * u[(j, keep[r])]))
}

/// Static condensation of the massless directions of the constrained space `Z`
/// (theory.md §4: massless rows add `(Kφ1)_massless = 0`), for blocks whose `B1` is singular.
///
/// The massless directions are decided on `F Z` (`FᵀF = B1`) by its singular values, not on
/// the eigenvalues of `ZᵀB1Z` (their squares): an Euler–Bernoulli section (rigid shear,
/// massless rotation) slaves the node rotations to the deflections through the trapezoidal
/// shear rows, so that `F Z` has genuine singular values down to `≈ 0.74/N²` of its largest
/// (measured, clamped and free ends, 10–400 elements) beside exact zeros (a free end's
/// alternating rotation). Their squares, the eigenvalues of `ZᵀB1Z`, fall below a `1e-10`
/// cut-off from about 270 elements on; the `F Z` test keeps them apart to `N ≈ 10⁵`. A failed
/// Cholesky of `ZᵀB1Z` is no test: it misses exact zeros at 20, 50, 200 and 400 elements
/// (round-off pivots) and leaves spurious `ω² ≈ 1e20–1e23`. The massless
/// coordinates `b` are then eliminated by least squares on the strain map
/// `S = L2⁻¹D_eᵀZ` (minimum strain energy, `(ZN)ᵀKφ1 = 0`, without forming `K`), and the
/// returned `L1` (lower, `L1L1ᵀ = ZᵀB1Z` on the new `Z`) comes from the QR factor of `F Z`,
/// again without squaring. Returns the new `Z` and `L1`.
fn condense_massless(
    f: &Mat<f64>,
    z: &Mat<f64>,
    de: &Mat<f64>,
    l2: &Mat<f64>,
    tol: f64,
) -> Result<(Mat<f64>, Mat<f64>)> {
    let numerical =
        |stage: &str, e: String| ModalError::Numerical { stage: stage.into(), reason: e };
    let nz = z.ncols();
    let fz = f * z;
    // (rank, V): a block without any mass (no rows in F) is massless in every direction
    let (rank, v) = if fz.nrows() == 0 {
        (0, Mat::<f64>::identity(nz, nz))
    } else {
        let svd =
            fz.svd().map_err(|e| numerical("SVD of the mass factor on Z", format!("{e:?}")))?;
        let s = svd.S().column_vector();
        let smax = (0..s.nrows()).map(|i| s[i]).fold(0.0f64, f64::max);
        ((0..s.nrows()).filter(|&i| s[i] > tol * smax).count(), svd.V().to_owned())
    };
    let z_new = if rank == nz {
        z.to_owned()
    } else {
        let vr = v.get(.., ..rank).to_owned();
        let vn = v.get(.., rank..).to_owned();
        // strain map of the massive and massless directions, S = L2⁻¹ D_eᵀ Z
        let mut sz = de.transpose() * z;
        l2.solve_lower_triangular_in_place(sz.as_mut());
        let (s_r, s_n) = (&sz * &vr, &sz * &vn);
        let n_massless = nz - rank;
        let scale = max_abs(sz.as_ref()).max(f64::MIN_POSITIVE);
        let without_stiffness = |smallest: f64| {
            numerical(
                "static condensation of massless directions",
                format!(
                    "{n_massless} massless direction(s) of a block without stiffness of their own \
                     (the smallest strain singular value is {smallest:e} of {scale:e}): a \
                     massless mechanism has no dynamics"
                ),
            )
        };
        if s_n.nrows() < n_massless {
            return Err(without_stiffness(0.0));
        }
        let svd_n =
            s_n.svd().map_err(|e| numerical("SVD of the massless strain map", format!("{e:?}")))?;
        let sn = svd_n.S().column_vector();
        if (0..n_massless).any(|i| sn[i] <= tol * scale || !sn[i].is_finite()) {
            return Err(without_stiffness(
                (0..n_massless).map(|i| sn[i]).fold(f64::INFINITY, f64::min),
            ));
        }
        // b = −(S N)⁺ S V_r a: the least-squares (minimum strain energy) massless part
        let (un, vn_s) = (svd_n.U(), svd_n.V());
        let mut coef = un.get(.., ..n_massless).transpose() * &s_r; // n_massless × rank
        for i in 0..n_massless {
            let inv = 1.0 / sn[i];
            for j in 0..rank {
                coef[(i, j)] *= inv;
            }
        }
        let b = vn_s * &coef; // n_massless × rank
        z * (&vr - &vn * &b)
    };
    if rank == 0 {
        return Ok((Mat::zeros(z.nrows(), 0), Mat::zeros(0, 0)));
    }
    let qr = (f * &z_new).qr();
    let t = qr.thin_R();
    let l1 = t.transpose().to_owned();
    if (0..l1.nrows()).any(|i| l1[(i, i)] == 0.0 || !l1[(i, i)].is_finite()) {
        return Err(numerical(
            "QR of the reduced mass factor",
            "massless directions left after condensation".into(),
        ));
    }
    Ok((z_new, l1))
}

/// One decoupled block's solution before rigid/elastic classification.
struct BlockSolution {
    s1: Vec<usize>,
    elastic_cols: Vec<usize>,
    lambda: Vec<f64>,
    phi1: Mat<f64>,
    /// `φ2 = B2e⁻¹ D_eᵀ φ1 / ω` of each column (zero where `ω = 0`), |elastic| × modes.
    phi2: Mat<f64>,
}

fn solve_block(
    p: &SecondOrderProblem,
    g: &Mat<f64>,
    s1: Vec<usize>,
    s2: Vec<usize>,
    g_rows: &[usize],
    tol: f64,
) -> Result<BlockSolution> {
    let b1 = gather(p.b1.as_ref(), &s1, &s1);
    let b2 = gather(p.b2.as_ref(), &s2, &s2);
    let d = gather(p.d.as_ref(), &s1, &s2);
    // Rigid element components: zero rows of B2 (C = 0 there, theory.md §1).
    let rigid: Vec<usize> =
        (0..s2.len()).filter(|&i| (0..s2.len()).all(|j| b2[(i, j)] == 0.0)).collect();
    let elastic: Vec<usize> = (0..s2.len()).filter(|i| rigid.binary_search(i).is_err()).collect();
    // Constraint rows: velocity rows, then D_rᵀ (rigid strain rows).
    let mut cons = Mat::<f64>::zeros(g_rows.len() + rigid.len(), s1.len());
    for (r, &gr) in g_rows.iter().enumerate() {
        for (c, &gi) in s1.iter().enumerate() {
            cons[(r, c)] = g[(gr, gi)];
        }
    }
    for (r, &rc) in rigid.iter().enumerate() {
        for c in 0..s1.len() {
            cons[(g_rows.len() + r, c)] = d[(c, rc)];
        }
    }
    let mut z = if cons.nrows() == 0 {
        Mat::<f64>::identity(s1.len(), s1.len())
    } else {
        intrinsic_beam::null_space(cons.as_ref(), tol)?.basis
    };
    let b2e = gather(b2.as_ref(), &elastic, &elastic);
    let all1: Vec<usize> = (0..s1.len()).collect();
    let de = gather(d.as_ref(), &all1, &elastic);
    // B2e = L2 L2ᵀ (block diagonal, SPD on the non-rigid entries)
    let l2 = if elastic.is_empty() {
        Mat::<f64>::zeros(0, 0)
    } else {
        b2e.llt(Side::Lower)
            .map_err(|e| ModalError::Numerical {
                stage: "Cholesky of an element compliance block B2".into(),
                reason: format!(
                    "{e:?} (a compliance matrix C must be positive definite on its non-rigid entries)"
                ),
            })?
            .L()
            .to_owned()
    };
    // Massless directions. A block whose B1 has a null space (a zero diagonal entry of a
    // diagonal B1, e.g. the rotation of an Euler–Bernoulli section; eigenvalues ≤ tol · max of
    // a non-diagonal one) goes through `condense_massless` whatever the conditioning of ZᵀB1Z;
    // other blocks (every paper section) keep the plain Cholesky route, unchanged.
    let mut l1 = None;
    if z.ncols() > 0 {
        let f = mass_factor(&b1, tol)?;
        let massless_coordinates = f.nrows() < s1.len();
        let mut b1r = z.transpose() * &b1 * &z;
        symmetrize(&mut b1r);
        let chol = if massless_coordinates { None } else { b1r.llt(Side::Lower).ok() };
        match chol {
            Some(c) => l1 = Some(c.L().to_owned()),
            None => {
                let (z_new, l1_new) = condense_massless(&f, &z, &de, &l2, tol)?;
                z = z_new;
                l1 = Some(l1_new);
            }
        }
    }
    let nz = z.ncols();
    let elastic_cols: Vec<usize> = elastic.iter().map(|&i| s2[i]).collect();
    let Some(l1) = l1.filter(|_| nz > 0) else {
        return Ok(BlockSolution {
            s1,
            elastic_cols,
            lambda: vec![],
            phi1: Mat::zeros(all1.len(), 0),
            phi2: Mat::zeros(elastic.len(), 0),
        });
    };
    // M = L2⁻¹ D_eᵀ Z L1⁻ᵀ, so that L1⁻¹ ZᵀKZ L1⁻ᵀ = MᵀM: the singular values of M are the
    // frequencies ω (no squaring of the condition number), its right singular vectors give
    // φ1 = Z L1⁻ᵀ v and its left ones φ2 = L2⁻ᵀ u = B2⁻¹Dᵀφ1/ω, exactly C-orthonormal.
    let mut y = de.transpose() * &z; // |e| × nz
    l2.solve_lower_triangular_in_place(y.as_mut());
    let mut mt = y.transpose().to_owned(); // nz × |e|
    l1.solve_lower_triangular_in_place(mt.as_mut());
    let svd = mt.transpose().to_owned().svd().map_err(|e| ModalError::Numerical {
        stage: "SVD of L2⁻¹DᵀZL1⁻ᵀ".into(),
        reason: format!("{e:?}"),
    })?;
    let sv = svd.S().column_vector();
    let ns = sv.nrows();
    let mut v = svd.V().to_owned(); // nz × nz
    let u = svd.U(); // |e| × |e|
    let lambda: Vec<f64> = (0..nz).map(|i| if i < ns { sv[i] * sv[i] } else { 0.0 }).collect();
    l1.transpose().solve_upper_triangular_in_place(v.as_mut());
    let phi1 = &z * &v;
    let mut w2 = Mat::<f64>::zeros(elastic.len(), nz);
    for j in 0..ns.min(nz) {
        if sv[j] > 0.0 {
            for i in 0..elastic.len() {
                w2[(i, j)] = u[(i, j)];
            }
        }
    }
    l2.transpose().solve_upper_triangular_in_place(w2.as_mut());
    Ok(BlockSolution { s1, elastic_cols, lambda, phi1, phi2: w2 })
}

/// Solves the constrained eigenproblem (see the module docs).
///
/// `rigid_candidates` (columns of length n1, in priority order) fix the basis of the
/// degenerate rigid-body eigenspace: those that are exact mechanism motions of the discrete
/// model (`G1 c = 0`, `Dᵀ c = 0`) become the first rigid modes, `B1`-orthonormalised in order
/// (theory.md §4: rotation about the root first, then joint by joint), and the elastic
/// problem is solved `B1`-orthogonal to them. Any rigid direction they miss is found by the
/// eigen solver and fixed by projecting the unit vectors `e_0, e_1, …` (deterministic but not
/// physically ordered).
pub fn solve(
    problem: &SecondOrderProblem,
    settings: &EigenSettings,
    rigid_candidates: Option<MatRef<'_, f64>>,
) -> Result<RawModes> {
    settings.validate()?;
    let (n1, n2) = (problem.n1(), problem.n2());
    if let Some(c) = rigid_candidates {
        if c.nrows() != n1 {
            return Err(shape("rigid_candidates", (n1, c.ncols()), (c.nrows(), c.ncols())));
        }
        check_finite("rigid_candidates", c)?;
    }
    // Exact rigid fields among the candidates; the elastic problem is solved B1-orthogonal
    // to them (extra constraint rows), so they are exact rigid modes.
    let exact = exact_rigid_fields(problem, rigid_candidates);
    let mut g_ext = Mat::<f64>::zeros(problem.g.nrows() + exact.len(), n1);
    for r in 0..problem.g.nrows() {
        for c in 0..n1 {
            g_ext[(r, c)] = problem.g[(r, c)];
        }
    }
    for (e, (_, bv)) in exact.iter().enumerate() {
        for c in 0..n1 {
            g_ext[(problem.g.nrows() + e, c)] = bv[c];
        }
    }
    // Connected components over X1 ∪ X2 unknowns.
    let mut uf = UnionFind((0..n1 + n2).collect());
    for j in 0..n1 {
        for i in 0..n1 {
            if problem.b1[(i, j)] != 0.0 {
                uf.union(i, j);
            }
        }
        for e in 0..n2 {
            if problem.d[(j, e)] != 0.0 {
                uf.union(j, n1 + e);
            }
        }
    }
    for j in 0..n2 {
        for i in 0..n2 {
            if problem.b2[(i, j)] != 0.0 {
                uf.union(n1 + i, n1 + j);
            }
        }
    }
    let g = &g_ext;
    let mut row_anchor = vec![None; g.nrows()];
    for r in 0..g.nrows() {
        let cols: Vec<usize> = (0..n1).filter(|&c| g[(r, c)] != 0.0).collect();
        for w in cols.windows(2) {
            uf.union(w[0], w[1]);
        }
        row_anchor[r] = cols.first().copied();
    }
    let mut roots: Vec<usize> = Vec::new();
    let mut members1: Vec<Vec<usize>> = Vec::new();
    let mut members2: Vec<Vec<usize>> = Vec::new();
    let mut block_of_root = std::collections::HashMap::new();
    for i in 0..n1 + n2 {
        let r = uf.find(i);
        let b = *block_of_root.entry(r).or_insert_with(|| {
            roots.push(r);
            members1.push(Vec::new());
            members2.push(Vec::new());
            roots.len() - 1
        });
        if i < n1 {
            members1[b].push(i);
        } else {
            members2[b].push(i - n1);
        }
    }
    let mut g_rows_of: Vec<Vec<usize>> = vec![Vec::new(); roots.len()];
    for (r, anchor) in row_anchor.iter().enumerate() {
        if let Some(a) = anchor {
            let root = uf.find(*a);
            g_rows_of[block_of_root[&root]].push(r);
        }
    }
    let mut blocks = Vec::new();
    for b in 0..roots.len() {
        if members1[b].is_empty() {
            continue;
        }
        blocks.push(solve_block(
            problem,
            &g_ext,
            members1[b].clone(),
            members2[b].clone(),
            &g_rows_of[b],
            settings.rank_tolerance,
        )?);
    }
    let lambda_max = blocks.iter().flat_map(|b| b.lambda.iter().copied()).fold(0.0f64, f64::max);
    let threshold = settings.rigid_tolerance * lambda_max;
    // (λ, block, column) of every mode.
    let mut rigid_ids = Vec::new();
    let mut elastic_ids = Vec::new();
    for (bi, b) in blocks.iter().enumerate() {
        for (ci, &l) in b.lambda.iter().enumerate() {
            if l <= threshold {
                rigid_ids.push((bi, ci));
            } else {
                elastic_ids.push((l, bi, ci));
            }
        }
    }
    elastic_ids.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let n_exact = exact.len();
    let n_rigid = n_exact + rigid_ids.len();
    let m = n_rigid + elastic_ids.len();
    let mut phi1 = Mat::<f64>::zeros(n1, m);
    let mut phi2 = Mat::<f64>::zeros(n2, m);
    let mut lambda = vec![0.0; m];
    let mut omega = vec![0.0; m];
    // Rigid modes: the exact fields, then a canonical basis of what is left of the space.
    for (j, (v, _)) in exact.iter().enumerate() {
        for i in 0..n1 {
            phi1[(i, j)] = v[i];
        }
    }
    let mut rigid = Mat::<f64>::zeros(n1, rigid_ids.len());
    for (col, &(bi, ci)) in rigid_ids.iter().enumerate() {
        let b = &blocks[bi];
        for (li, &gi) in b.s1.iter().enumerate() {
            rigid[(gi, col)] = b.phi1[(li, ci)];
        }
        lambda[n_exact + col] = b.lambda[ci];
    }
    let canonical = canonical_rigid_basis(&problem.b1, &rigid)?;
    for j in 0..rigid_ids.len() {
        for i in 0..n1 {
            phi1[(i, n_exact + j)] = canonical[(i, j)];
        }
    }
    for (k, &(l, bi, ci)) in elastic_ids.iter().enumerate() {
        let col = n_rigid + k;
        let b = &blocks[bi];
        let w = l.sqrt();
        lambda[col] = l;
        omega[col] = w;
        // Deterministic sign: the largest |component| of φ1 (first index on ties) positive.
        let vals: Vec<f64> = (0..b.s1.len()).map(|i| b.phi1[(i, ci)]).collect();
        let sign = sign_of_largest(&vals);
        for (li, &gi) in b.s1.iter().enumerate() {
            phi1[(gi, col)] = sign * vals[li];
        }
        for (le, &ge) in b.elastic_cols.iter().enumerate() {
            phi2[(ge, col)] = sign * b.phi2[(le, ci)];
        }
    }
    Ok(RawModes {
        lambda,
        omega,
        phi1,
        phi2,
        n_rigid,
        lambda_max,
        block_sizes: blocks.iter().map(|b| b.phi1.ncols()).collect(),
    })
}

/// `+1` or `−1` so that the largest-magnitude entry (first one within 1e-6 relative) is positive.
pub(crate) fn sign_of_largest(vals: &[f64]) -> f64 {
    let max = vals.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    match vals.iter().find(|v| v.abs() >= max * (1.0 - 1e-6)) {
        Some(v) if *v < 0.0 => -1.0,
        _ => 1.0,
    }
}

/// Admissible rigid candidates (`G1 c = 0`, `Dᵀ c = 0` to round-off: exact mechanism motions
/// of the discrete model), made `B1`-orthonormal in order: `(field, B1 field)` pairs.
fn exact_rigid_fields(
    problem: &SecondOrderProblem,
    candidates: Option<MatRef<'_, f64>>,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let Some(c) = candidates else { return Vec::new() };
    let (gmax, dmax) = (max_abs(problem.g.as_ref()), max_abs(problem.d.as_ref()));
    let gres = &problem.g * c;
    let dres = problem.d.transpose() * c;
    let bc = &problem.b1 * c;
    admissible_rigid_fields(c, gres.as_ref(), dres.as_ref(), bc.as_ref(), gmax, dmax)
}

/// The candidates `c` whose residuals `G1 c` (`gres`) and `Dᵀ c` (`dres`) are below `1e-10`
/// of `max|G1| max|c|` and `max|D| max|c|`, `B1`-orthonormalised in order (Gram–Schmidt,
/// twice; `bc = B1 c`), dropping those left with under `1e-6` of their norm.
pub(crate) fn admissible_rigid_fields(
    c: MatRef<'_, f64>,
    gres: MatRef<'_, f64>,
    dres: MatRef<'_, f64>,
    bc: MatRef<'_, f64>,
    gmax: f64,
    dmax: f64,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let n1 = c.nrows();
    let mut done: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    for col in 0..c.ncols() {
        let vmax = (0..n1).fold(0.0f64, |a, i| a.max(c[(i, col)].abs()));
        if vmax == 0.0 {
            continue;
        }
        let g = (0..gres.nrows()).fold(0.0f64, |a, i| a.max(gres[(i, col)].abs()));
        let d = (0..dres.nrows()).fold(0.0f64, |a, i| a.max(dres[(i, col)].abs()));
        if g > 1e-10 * gmax * vmax || d > 1e-10 * dmax * vmax {
            continue;
        }
        let mut v: Vec<f64> = (0..n1).map(|i| c[(i, col)]).collect();
        let mut bv: Vec<f64> = (0..n1).map(|i| bc[(i, col)]).collect();
        let n0 = bv.iter().zip(&v).map(|(x, y)| x * y).sum::<f64>().max(0.0).sqrt();
        for _ in 0..2 {
            for (q, bq) in &done {
                let a: f64 = bq.iter().zip(&v).map(|(x, y)| x * y).sum();
                for i in 0..n1 {
                    v[i] -= a * q[i];
                    bv[i] -= a * bq[i];
                }
            }
        }
        let n = bv.iter().zip(&v).map(|(x, y)| x * y).sum::<f64>().max(0.0).sqrt();
        if n > 1e-6 * n0 {
            done.push((v.iter().map(|x| x / n).collect(), bv.iter().map(|x| x / n).collect()));
        }
    }
    done
}

/// Canonical basis of the rigid eigenspace spanned by the `B1`-orthonormal columns of `rigid`:
/// the projections of the unit vectors `e_0, e_1, …` onto it, orthonormalised in order.
fn canonical_rigid_basis(b1: &Mat<f64>, rigid: &Mat<f64>) -> Result<Mat<f64>> {
    if rigid.ncols() == 0 {
        return Ok(Mat::zeros(rigid.nrows(), 0));
    }
    canonical_rigid_basis_of(&(b1 * rigid), rigid)
}

/// [`canonical_rigid_basis`] given `b1r = B1 R` (the coordinates of `c` in the rigid basis are
/// `(B1 R)ᵀ c`).
pub(crate) fn canonical_rigid_basis_of(b1r: &Mat<f64>, rigid: &Mat<f64>) -> Result<Mat<f64>> {
    let (n1, r) = (rigid.nrows(), rigid.ncols());
    if r == 0 {
        return Ok(Mat::zeros(n1, 0));
    }
    let row_norm_max = (0..n1)
        .map(|i| (0..r).map(|j| b1r[(i, j)].powi(2)).sum::<f64>().sqrt())
        .fold(0.0f64, f64::max);
    let mut coords: Vec<Vec<f64>> = Vec::new();
    for i in 0..n1 {
        if coords.len() == r {
            break;
        }
        let a: Vec<f64> = (0..r).map(|j| b1r[(i, j)]).collect();
        let norm0 = a.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm0 <= 1e-8 * row_norm_max {
            continue;
        }
        let mut p = a;
        for _ in 0..2 {
            for q in coords.iter() {
                let dot: f64 = p.iter().zip(q).map(|(x, y)| x * y).sum();
                for (x, y) in p.iter_mut().zip(q) {
                    *x -= dot * y;
                }
            }
        }
        let norm = p.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-6 * norm0 {
            coords.push(p.into_iter().map(|x| x / norm).collect());
        }
    }
    if coords.len() != r {
        return Err(ModalError::Numerical {
            stage: "canonical rigid basis".into(),
            reason: format!("found {} of {r} directions", coords.len()),
        });
    }
    let coords = Mat::from_fn(r, r, |i, j| coords[j][i]);
    Ok(rigid * &coords)
}
