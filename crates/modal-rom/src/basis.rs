//! The modal basis: frequencies, velocity/force modes per beam, labels, selection (§3.2).

use crate::blocks::BlockDiag;
use crate::eigen::{solve, EigenSettings, RawModes, SecondOrderProblem};
use crate::error::{invalid, shape, ModalError, Result};
use crate::layout::{Components, Layout};
use faer::{Mat, MatRef};
use serde::{Deserialize, Serialize};

/// The kind of a mode, from its energy split (theory.md §4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModeKind {
    /// `ω = 0`, `φ2 ≡ 0`: a mechanism (rigid-body) motion.
    Rigid,
    /// Energy mainly in `v1`/`f1` (local components).
    Axial,
    /// Energy mainly in `ω1`/`m1`.
    Torsion,
    /// Bending about e2 (deflection along e3): `v3, ω2 / f3, m2`. The planar bending family.
    BendingE2,
    /// Bending about e3 (deflection along e2): `v2, ω3 / f2, m3`.
    BendingE3,
    /// No family holds the label threshold of the energy.
    Mixed,
}

impl ModeKind {
    /// Every kind, in the order used by [`KindCounts`] and the energy fractions.
    pub const ALL: [ModeKind; 6] = [
        ModeKind::Rigid,
        ModeKind::Axial,
        ModeKind::Torsion,
        ModeKind::BendingE2,
        ModeKind::BendingE3,
        ModeKind::Mixed,
    ];

    /// Label text: `rigid`, `axial`, `torsion`, `bending` (planar) / `bending-e2`, `bending-e3`, `mixed`.
    pub fn label(self, components: Components) -> &'static str {
        match (self, components) {
            (ModeKind::Rigid, _) => "rigid",
            (ModeKind::Axial, _) => "axial",
            (ModeKind::Torsion, _) => "torsion",
            (ModeKind::BendingE2, Components::Planar) => "bending",
            (ModeKind::BendingE2, Components::Spatial) => "bending-e2",
            (ModeKind::BendingE3, _) => "bending-e3",
            (ModeKind::Mixed, _) => "mixed",
        }
    }

    /// Family of spatial component index `s` (0..6) of either field.
    fn family(s: usize) -> usize {
        // 0 axial, 1 torsion, 2 bending-e2, 3 bending-e3
        [0, 3, 2, 1, 2, 3][s]
    }
}

/// Kind and energy fractions `[axial, torsion, bending-e2, bending-e3]` of one mode from its
/// kinetic terms `φ1ᵢ (B1φ1)ᵢ` and strain terms `φ2ᵢ (B2φ2)ᵢ`, in index order (local component
/// `i mod k`): the mean of the kinetic and strain fractions of each family; a family holding at
/// least `threshold` of it names the mode, else `mixed`; `rigid` modes are `Rigid`.
pub(crate) fn classify(
    comps: Components,
    rigid: bool,
    threshold: f64,
    kinetic: impl Iterator<Item = f64>,
    strain: impl Iterator<Item = f64>,
) -> (ModeKind, [f64; 4]) {
    let k = comps.k();
    let mut kin = [0.0; 4];
    let mut stn = [0.0; 4];
    for (i, e) in kinetic.enumerate() {
        kin[ModeKind::family(comps.spatial_index(i % k))] += e;
    }
    for (i, e) in strain.enumerate() {
        stn[ModeKind::family(comps.spatial_index(i % k))] += e;
    }
    let (tk, ts) = (kin.iter().sum::<f64>(), stn.iter().sum::<f64>());
    let mut frac = [0.0; 4];
    for f in 0..4 {
        let a = if tk > 0.0 { kin[f] / tk } else { 0.0 };
        let b = if ts > 0.0 { stn[f] / ts } else { a };
        frac[f] = 0.5 * (a + b);
    }
    let kind = if rigid {
        ModeKind::Rigid
    } else {
        let (best, val) =
            frac.iter()
                .enumerate()
                .fold((0, f64::MIN), |acc, (i, &v)| if v > acc.1 { (i, v) } else { acc });
        if val >= threshold {
            [ModeKind::Axial, ModeKind::Torsion, ModeKind::BendingE2, ModeKind::BendingE3][best]
        } else {
            ModeKind::Mixed
        }
    };
    (kind, frac)
}

/// Settings of [`ModalBasis::compute`].
#[derive(Clone, Debug, PartialEq)]
pub struct BasisSettings {
    /// Eigen solver settings.
    pub eigen: EigenSettings,
    /// A mode is labelled by a family holding at least this fraction of its energy
    /// (mean of the kinetic and strain fractions), else `mixed`. Default `0.9`; range `(0.5, 1]`.
    pub label_threshold: f64,
}

impl Default for BasisSettings {
    fn default() -> Self {
        BasisSettings { eigen: EigenSettings::default(), label_threshold: 0.9 }
    }
}

impl BasisSettings {
    /// Checks the documented ranges.
    pub fn validate(&self) -> Result<()> {
        self.eigen.validate()?;
        if !(self.label_threshold > 0.5 && self.label_threshold <= 1.0) {
            return Err(invalid("label_threshold", self.label_threshold, "must lie in (0.5, 1]"));
        }
        Ok(())
    }
}

/// How many modes of each kind to keep (the lowest of each kind); absent kinds are 0 when
/// deserialised (a scene's `[modes] kinds = { rigid = 2, axial = 4, bending_e2 = 4 }`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KindCounts {
    /// Rigid-body modes.
    pub rigid: usize,
    /// Axial modes.
    pub axial: usize,
    /// Torsion modes.
    pub torsion: usize,
    /// Bending about e2 (planar bending).
    pub bending_e2: usize,
    /// Bending about e3.
    pub bending_e3: usize,
    /// Mixed modes.
    pub mixed: usize,
}

impl KindCounts {
    /// The paper's 2D model (§5.2): 2 rigid + 4 axial + 4 bending.
    pub fn paper_2d() -> Self {
        KindCounts { rigid: 2, axial: 4, bending_e2: 4, ..Default::default() }
    }

    /// The paper's 3D model (§5.3): 4 rigid + 4 axial + 4 torsion + 4 + 4 bending.
    pub fn paper_3d() -> Self {
        KindCounts { rigid: 4, axial: 4, torsion: 4, bending_e2: 4, bending_e3: 4, mixed: 0 }
    }

    fn get(&self, kind: ModeKind) -> usize {
        match kind {
            ModeKind::Rigid => self.rigid,
            ModeKind::Axial => self.axial,
            ModeKind::Torsion => self.torsion,
            ModeKind::BendingE2 => self.bending_e2,
            ModeKind::BendingE3 => self.bending_e3,
            ModeKind::Mixed => self.mixed,
        }
    }
}

/// Which modes a reduced model keeps.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModeSelection {
    /// The first `n` modes in basis order (rigid first, then by frequency).
    Lowest(usize),
    /// The lowest modes of each kind, kept in basis order.
    ByKind(KindCounts),
    /// Explicit mode indices (sorted and deduplicated before use).
    Indices(Vec<usize>),
}

impl ModeSelection {
    /// At least one mode: `Lowest(n)` with `n ≥ 1`, `ByKind` with a positive total, `Indices`
    /// non-empty. Errors name the form (`lowest`, `kinds`, `indices`); whether the basis has
    /// the modes is checked by [`ModalBasis::select`].
    pub fn validate(&self) -> Result<()> {
        match self {
            ModeSelection::Lowest(0) => Err(invalid("lowest", 0, "must be at least 1")),
            ModeSelection::ByKind(k)
                if k.rigid + k.axial + k.torsion + k.bending_e2 + k.bending_e3 + k.mixed == 0 =>
            {
                Err(invalid("kinds", "0 modes", "select at least one mode"))
            }
            ModeSelection::Indices(v) if v.is_empty() => {
                Err(invalid("indices", "[]", "give at least one mode index"))
            }
            _ => Ok(()),
        }
    }
}

/// Constrained modes of a structure (paper §3.2, theory.md §4).
///
/// Modes are columns: `phi1` (n1 × m, node values of `x1`, `B1`-orthonormal) and `phi2`
/// (n2 × m, element values of `x2`, `φ2 = B2⁻¹Dᵀφ1/ω`), rigid modes first in the canonical
/// basis, then elastic modes by increasing `ω`.
#[derive(Clone, Debug)]
pub struct ModalBasis {
    layout: Layout,
    b1: Mat<f64>,
    b2: Mat<f64>,
    b1_blocks: BlockDiag,
    b2_blocks: BlockDiag,
    d: Mat<f64>,
    omega: Vec<f64>,
    lambda: Vec<f64>,
    kinds: Vec<ModeKind>,
    fractions: Vec<[f64; 4]>,
    n_rigid: usize,
    phi1: Mat<f64>,
    phi2: Mat<f64>,
    lambda_max: f64,
    block_sizes: Vec<usize>,
}

impl ModalBasis {
    /// Solves the constrained eigenproblem and labels the modes. `rigid_candidates` fix the
    /// rigid-mode basis (see [`crate::eigen::solve`] and the `rigid` module).
    pub fn compute(
        layout: Layout,
        problem: &SecondOrderProblem,
        settings: &BasisSettings,
        rigid_candidates: Option<MatRef<'_, f64>>,
    ) -> Result<Self> {
        settings.validate()?;
        layout.validate()?;
        if problem.n1() != layout.n1() || problem.n2() != layout.n2() {
            return Err(shape(
                "problem (n1, n2) vs layout",
                (layout.n1(), layout.n2()),
                (problem.n1(), problem.n2()),
            ));
        }
        let b1_blocks = BlockDiag::from_dense("B1", problem.b1.as_ref(), layout.k())?;
        let b2_blocks = BlockDiag::from_dense("B2", problem.b2.as_ref(), layout.k())?;
        let raw = solve(problem, &settings.eigen, rigid_candidates)?;
        Ok(Self::from_raw(layout, problem, raw, settings.label_threshold, b1_blocks, b2_blocks))
    }

    fn from_raw(
        layout: Layout,
        problem: &SecondOrderProblem,
        raw: RawModes,
        threshold: f64,
        b1_blocks: BlockDiag,
        b2_blocks: BlockDiag,
    ) -> Self {
        let RawModes { lambda, omega, phi1, phi2, n_rigid, lambda_max, block_sizes } = raw;
        let mut basis = ModalBasis {
            layout,
            b1: problem.b1.clone(),
            b2: problem.b2.clone(),
            b1_blocks,
            b2_blocks,
            d: problem.d.clone(),
            omega,
            lambda,
            kinds: Vec::new(),
            fractions: Vec::new(),
            n_rigid,
            phi1,
            phi2,
            lambda_max,
            block_sizes,
        };
        basis.label(threshold);
        basis
    }

    fn label(&mut self, threshold: f64) {
        let comps = self.layout.components;
        let b1p = self.b1_blocks.apply(self.phi1.as_ref());
        let b2p = self.b2_blocks.apply(self.phi2.as_ref());
        let m = self.omega.len();
        self.kinds.clear();
        self.fractions.clear();
        for j in 0..m {
            let kinetic = (0..self.phi1.nrows()).map(|i| self.phi1[(i, j)] * b1p[(i, j)]);
            let strain = (0..self.phi2.nrows()).map(|i| self.phi2[(i, j)] * b2p[(i, j)]);
            let (kind, frac) = classify(comps, j < self.n_rigid, threshold, kinetic, strain);
            self.kinds.push(kind);
            self.fractions.push(frac);
        }
    }

    /// The structure layout.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// Number of modes `m`.
    pub fn n_modes(&self) -> usize {
        self.omega.len()
    }

    /// Number of rigid-body modes (the first ones).
    pub fn n_rigid(&self) -> usize {
        self.n_rigid
    }

    /// Frequencies `ω` in rad/s (0 for rigid modes).
    pub fn omega(&self) -> &[f64] {
        &self.omega
    }

    /// Eigenvalues `ω²` as computed (rigid ones are round-off, possibly slightly negative).
    pub fn lambda(&self) -> &[f64] {
        &self.lambda
    }

    /// Largest eigenvalue of the full discrete problem (conditioning reference).
    pub fn lambda_max(&self) -> f64 {
        self.lambda_max
    }

    /// Sizes of the decoupled blocks the eigen solver handled.
    pub fn block_sizes(&self) -> &[usize] {
        &self.block_sizes
    }

    /// Kind of each mode.
    pub fn kinds(&self) -> &[ModeKind] {
        &self.kinds
    }

    /// Labels of each mode (see [`ModeKind::label`]).
    pub fn labels(&self) -> Vec<String> {
        self.kinds.iter().map(|k| k.label(self.layout.components).to_string()).collect()
    }

    /// Energy fractions `[axial, torsion, bending-e2, bending-e3]` of each mode (mean of
    /// kinetic and strain fractions).
    pub fn energy_fractions(&self) -> &[[f64; 4]] {
        &self.fractions
    }

    /// Velocity modes (n1 × m).
    pub fn phi1(&self) -> MatRef<'_, f64> {
        self.phi1.as_ref()
    }

    /// Force modes (n2 × m).
    pub fn phi2(&self) -> MatRef<'_, f64> {
        self.phi2.as_ref()
    }

    /// Node mass operator `B1` (n1 × n1).
    pub fn b1(&self) -> MatRef<'_, f64> {
        self.b1.as_ref()
    }

    /// Element compliance operator `B2` (n2 × n2).
    pub fn b2(&self) -> MatRef<'_, f64> {
        self.b2.as_ref()
    }

    /// `B1` by blocks.
    pub fn b1_blocks(&self) -> &BlockDiag {
        &self.b1_blocks
    }

    /// `B2` by blocks.
    pub fn b2_blocks(&self) -> &BlockDiag {
        &self.b2_blocks
    }

    /// Coupling `D` (n1 × n2) of the linear operator.
    pub fn d(&self) -> MatRef<'_, f64> {
        self.d.as_ref()
    }

    /// `φ1` of mode `j` at node `n` of beam `b` (k values).
    pub fn phi1_at(&self, j: usize, b: usize, n: usize) -> Vec<f64> {
        let i0 = self.layout.x1_index(b, n, 0);
        (0..self.layout.k()).map(|c| self.phi1[(i0 + c, j)]).collect()
    }

    /// `φ2` of mode `j` at element `e` of beam `b` (k values).
    pub fn phi2_at(&self, j: usize, b: usize, e: usize) -> Vec<f64> {
        let i0 = self.layout.x2_index(b, e, 0);
        (0..self.layout.k()).map(|c| self.phi2[(i0 + c, j)]).collect()
    }

    /// The modes picked by `selection`, in basis order (rigid first, then by frequency).
    pub fn select(&self, selection: &ModeSelection) -> Result<ModalBasis> {
        selection.validate()?;
        let m = self.n_modes();
        let idx: Vec<usize> = match selection {
            ModeSelection::Lowest(n) => {
                if *n > m {
                    return Err(ModalError::NotEnoughModes {
                        kind: "any".into(),
                        requested: *n,
                        available: m,
                    });
                }
                (0..*n).collect()
            }
            ModeSelection::Indices(list) => {
                let mut v = list.clone();
                v.sort_unstable();
                v.dedup();
                if let Some(&bad) = v.iter().find(|&&i| i >= m) {
                    return Err(invalid("mode index", bad, format!("the basis has {m} modes")));
                }
                v
            }
            ModeSelection::ByKind(counts) => {
                let mut taken = Vec::new();
                for kind in ModeKind::ALL {
                    let want = counts.get(kind);
                    let have: Vec<usize> = (0..m).filter(|&j| self.kinds[j] == kind).collect();
                    if have.len() < want {
                        return Err(ModalError::NotEnoughModes {
                            kind: kind.label(self.layout.components).into(),
                            requested: want,
                            available: have.len(),
                        });
                    }
                    taken.extend_from_slice(&have[..want]);
                }
                taken.sort_unstable();
                taken
            }
        };
        let pick = |mat: &Mat<f64>| Mat::from_fn(mat.nrows(), idx.len(), |i, j| mat[(i, idx[j])]);
        Ok(ModalBasis {
            layout: self.layout.clone(),
            b1: self.b1.clone(),
            b2: self.b2.clone(),
            b1_blocks: self.b1_blocks.clone(),
            b2_blocks: self.b2_blocks.clone(),
            d: self.d.clone(),
            omega: idx.iter().map(|&j| self.omega[j]).collect(),
            lambda: idx.iter().map(|&j| self.lambda[j]).collect(),
            kinds: idx.iter().map(|&j| self.kinds[j]).collect(),
            fractions: idx.iter().map(|&j| self.fractions[j]).collect(),
            n_rigid: idx.iter().filter(|&&j| j < self.n_rigid).count(),
            phi1: pick(&self.phi1),
            phi2: pick(&self.phi2),
            lambda_max: self.lambda_max,
            block_sizes: self.block_sizes.clone(),
        })
    }

    /// Orthonormality and duality residuals: `max|Φ1ᵀB1Φ1 − I|`, `max|Φ2ᵀB2Φ2 − I|` over elastic
    /// modes, and `max|Φ1ᵀDΦ2 − Ω|` (the paper's sign, eq. 15).
    pub fn orthonormality_residuals(&self) -> (f64, f64, f64) {
        let m = self.n_modes();
        let r = self.n_rigid;
        let s1 = self.phi1.transpose() * self.b1_blocks.apply(self.phi1.as_ref());
        let s2 = self.phi2.transpose() * self.b2_blocks.apply(self.phi2.as_ref());
        let dd = self.phi1.transpose() * &self.d * &self.phi2;
        let (mut e1, mut e2, mut e3) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..m {
            for j in 0..m {
                let delta = if i == j { 1.0 } else { 0.0 };
                e1 = e1.max((s1[(i, j)] - delta).abs());
                if i >= r && j >= r {
                    e2 = e2.max((s2[(i, j)] - delta).abs());
                }
                let target = if i == j { self.omega[i] } else { 0.0 };
                e3 = e3.max((dd[(i, j)] - target).abs());
            }
        }
        (e1, e2, e3)
    }
}
