//! Per-link fields and their Galerkin operators (theory.md §10.2).
//!
//! A [`LinkBasis`] holds velocity fields `Φ1` and force fields `Φ2`, each supported on one link
//! only, in that link's local components (the FE unknowns `X1`, `X2` of theory.md §2), with
//! `Φ1ᵀB1Φ1 = I` and `Φ2ᵀB2Φ2 = I`. The link fields are the per-link pieces of given
//! structure fields (constrained modes at one or several reference angles), optionally
//! with the link's six rigid motions, orthonormalised link by link with rank truncation; the
//! force fields span the strain images `B2⁻¹Dᵀφ1` of the velocity fields (the paper's
//! `φ2 ∝ B2⁻¹Dᵀφ1`, split per link). The Galerkin operators on them are those of (14)–(20):
//!
//! ```text
//!   f1 = Σ q1 + W q2 − q1_l Γ1^l q1 − q2_l Γ2^l q2 + B_u u,   f2 = −Wᵀ q1 + q2_l (Γ2^l)ᵀ q1,
//!   W = Φ1ᵀ D Φ2,  Σ = Φ1ᵀ D_damp Φ1,  Γ1^l_ij = ⟨φ1i, L1(φ1j) M φ1l⟩,  Γ2^l_ij = ⟨φ1i, L2(φ2j) C φ2l⟩,
//! ```
//!
//! without the joints' reactions: those enter the reduced model as workless constraint
//! forces (theory.md §10.3). `q1ᵀf1 + q2ᵀf2 = q1ᵀΣq1 + q1ᵀB_u u` for every `(q1, q2)`.

use crate::error::{invalid, shape, ModalError, Result};
use crate::exact_joints::frame::{gemv, gemv_t, matvec};
use crate::layout::Layout;
use crate::rom::Input;
use crate::structure::StructureModel;
use faer::linalg::solvers::Solve;
use faer::{Mat, MatRef, Side};
use intrinsic_beam::operators::{l1_times, l2_times};
use intrinsic_beam::rotation::rotation;
use nalgebra::{Vector3, Vector6};

/// One link's `((first velocity column, count), (first force column, count), Γ1, Γ2)`.
pub(crate) type LinkGammas<'a> = ((usize, usize), (usize, usize), &'a [f64], &'a [f64]);

/// Settings of [`LinkBasis::from_fields`].
#[derive(Clone, Debug, PartialEq)]
pub struct LinkBasisSettings {
    /// Add each link's rigid motions (translations and rotations about its start node) to
    /// its fields. Default `true`.
    pub rigid_links: bool,
    /// A per-link field direction is kept when its Gram eigenvalue exceeds this fraction of
    /// the largest. Default `1e-10`; range `(0, 1e-4]`.
    pub rank_tolerance: f64,
}

impl Default for LinkBasisSettings {
    fn default() -> Self {
        LinkBasisSettings { rigid_links: true, rank_tolerance: 1e-10 }
    }
}

impl LinkBasisSettings {
    /// Checks the documented ranges.
    pub fn validate(&self) -> Result<()> {
        if !(self.rank_tolerance > 0.0 && self.rank_tolerance <= 1e-4) {
            return Err(invalid("rank_tolerance", self.rank_tolerance, "must lie in (0, 1e-4]"));
        }
        Ok(())
    }
}

/// Per-link orthonormal velocity and force fields (theory.md §10.2).
#[derive(Clone, Debug)]
pub struct LinkBasis {
    pub(crate) layout: Layout,
    /// `n1 × na`, `B1`-orthonormal, columns grouped by link.
    pub(crate) phi1: Mat<f64>,
    /// `n2 × nb`, `B2`-orthonormal, columns grouped by link.
    pub(crate) phi2: Mat<f64>,
    /// Column range of each link in `phi1`.
    pub(crate) cols1: Vec<(usize, usize)>,
    /// Column range of each link in `phi2`.
    pub(crate) cols2: Vec<(usize, usize)>,
    pub(crate) b1: Mat<f64>,
    pub(crate) b2: Mat<f64>,
    pub(crate) d: Mat<f64>,
}

impl LinkBasis {
    /// The fields `Φ1 N` for a reduction `N` (`na × n`, orthonormal columns, block-diagonal
    /// by link: [`crate::exact_joints::rows::Constraints::support_reduction`]); the force
    /// fields unchanged.
    pub(crate) fn reduced(&self, reduce: &Mat<f64>) -> LinkBasis {
        let mut cols1 = Vec::new();
        let mut o = 0;
        for &(c0, c1) in &self.cols1 {
            let k =
                (0..reduce.ncols()).filter(|&j| (c0..c1).any(|i| reduce[(i, j)] != 0.0)).count();
            cols1.push((o, o + k));
            o += k;
        }
        LinkBasis {
            layout: self.layout.clone(),
            phi1: &self.phi1 * reduce,
            phi2: self.phi2.clone(),
            cols1,
            cols2: self.cols2.clone(),
            b1: self.b1.clone(),
            b2: self.b2.clone(),
            d: self.d.clone(),
        }
    }
}

/// `B`-orthonormal basis of the columns of `f` (rows `r0..r1` of the block `b`), by the
/// eigenvectors of the Gram matrix, largest first, eigenvalues below `tol · max` dropped;
/// sign fixed so that the largest |entry| of each column is positive.
fn orthonormalise(f: &Mat<f64>, b: MatRef<'_, f64>, tol: f64, what: &str) -> Result<Mat<f64>> {
    if f.ncols() == 0 {
        return Ok(Mat::zeros(f.nrows(), 0));
    }
    let bf = b * f;
    let gram = f.transpose() * &bf;
    let gram = Mat::from_fn(gram.nrows(), gram.ncols(), |i, j| 0.5 * (gram[(i, j)] + gram[(j, i)]));
    let eig = gram.self_adjoint_eigen(Side::Lower).map_err(|e| ModalError::Numerical {
        stage: format!("Gram matrix of the {what} fields"),
        reason: format!("{e:?}"),
    })?;
    let s = eig.S().column_vector();
    let u = eig.U();
    let n = s.nrows();
    let smax = (0..n).map(|i| s[i]).fold(0.0f64, f64::max);
    let mut keep: Vec<usize> = (0..n).filter(|&i| smax > 0.0 && s[i] > tol * smax).collect();
    keep.sort_by(|&a, &b| s[b].total_cmp(&s[a]).then(a.cmp(&b)));
    let mut out = Mat::<f64>::zeros(f.nrows(), keep.len());
    for (c, &e) in keep.iter().enumerate() {
        let scale = 1.0 / s[e].sqrt();
        for j in 0..f.ncols() {
            let w = u[(j, e)] * scale;
            if w == 0.0 {
                continue;
            }
            for i in 0..f.nrows() {
                out[(i, c)] += f[(i, j)] * w;
            }
        }
    }
    // The Gram eigenvectors of the small eigenvalues carry errors of `ε λ_max / λ`, so the
    // columns above are `B`-orthonormal only to that (1e-7 for strain images of near-rigid
    // link pieces); two Cholesky–QR passes `Y ← Y R⁻¹`, `RᵀR = YᵀBY`, restore orthonormality
    // to round-off without leaving `span f` (a triangular change of size of that error).
    for _ in 0..2 {
        let g = out.transpose() * (b * &out);
        let g = Mat::from_fn(g.nrows(), g.ncols(), |i, j| 0.5 * (g[(i, j)] + g[(j, i)]));
        let l = g.llt(Side::Lower).map_err(|e| ModalError::Numerical {
            stage: format!("re-orthonormalisation of the {what} fields"),
            reason: format!("{e:?}"),
        })?;
        let lt = l.L().to_owned();
        let mut t = out.transpose().to_owned();
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(
            lt.as_ref(),
            t.as_mut(),
            faer::Par::Seq,
        );
        out = t.transpose().to_owned();
    }
    for c in 0..out.ncols() {
        let (mut big, mut at) = (0.0f64, 0);
        for i in 0..f.nrows() {
            if out[(i, c)].abs() > big + 1e-12 * big {
                big = out[(i, c)].abs();
                at = i;
            }
        }
        if out[(at, c)] < 0.0 {
            for i in 0..f.nrows() {
                out[(i, c)] = -out[(i, c)];
            }
        }
    }
    Ok(out)
}

fn sub(m: &Mat<f64>, r: (usize, usize), c: (usize, usize)) -> Mat<f64> {
    Mat::from_fn(r.1 - r.0, c.1 - c.0, |i, j| m[(r.0 + i, c.0 + j)])
}

impl LinkBasis {
    /// Per-link fields from structure fields `fields` (each `n1 × s`, node velocities in local
    /// components, e.g. constrained modes of the structure at several reference angles; all
    /// must share the layout of `model`), plus the links' rigid motions when asked.
    pub fn from_fields(
        model: &StructureModel,
        fields: &[MatRef<'_, f64>],
        settings: &LinkBasisSettings,
    ) -> Result<Self> {
        Self::from_fields_and_forces(model, fields, None, settings)
    }

    /// As [`LinkBasis::from_fields`], with the force fields the per-link pieces of the given
    /// structure force fields `forces` (`n2 × s`, e.g. the modes' `Φ2`) instead of the strain
    /// images `B2⁻¹DᵀΦ1` of the velocity fields: for fields whose force partners are
    /// `φ2 ∝ B2⁻¹Dᵀφ1` (the paper's modes) the span is the same, and the given `φ2` are then
    /// re-expanded to round-off (the strain images hold them only to the modes' eigen residual).
    pub fn from_fields_and_forces(
        model: &StructureModel,
        fields: &[MatRef<'_, f64>],
        forces: Option<MatRef<'_, f64>>,
        settings: &LinkBasisSettings,
    ) -> Result<Self> {
        settings.validate()?;
        let layout = model.layout.clone();
        let (n1, n2, k) = (layout.n1(), layout.n2(), layout.k());
        for (i, f) in fields.iter().enumerate() {
            if f.nrows() != n1 {
                return Err(shape(format!("fields[{i}]"), (n1, f.ncols()), (f.nrows(), f.ncols())));
            }
        }
        let prob = &model.problem;
        let mut blocks1 = Vec::new();
        let mut cols1 = Vec::new();
        let mut total = 0;
        for (b, beam) in layout.beams.iter().enumerate() {
            let r = (layout.x1_offset(b), layout.x1_offset(b) + k * beam.n_nodes());
            let mut cols: Vec<Vec<f64>> = Vec::new();
            if settings.rigid_links {
                let r0 = beam.position(0);
                for m in 0..6 {
                    let mut col = vec![0.0; r.1 - r.0];
                    for n in 0..beam.n_nodes() {
                        let t = rotation(&beam.xi(n));
                        let (v, w) = if m < 3 {
                            (Vector3::ith(m, 1.0), Vector3::zeros())
                        } else {
                            let w = Vector3::ith(m - 3, 1.0);
                            (w.cross(&(beam.position(n) - r0)), w)
                        };
                        let (vl, wl) = (t.transpose() * v, t.transpose() * w);
                        let full = Vector6::new(vl.x, vl.y, vl.z, wl.x, wl.y, wl.z);
                        for c in 0..k {
                            col[n * k + c] = full[layout.components.spatial_index(c)];
                        }
                    }
                    cols.push(col);
                }
            }
            for f in fields {
                for j in 0..f.ncols() {
                    cols.push((r.0..r.1).map(|i| f[(i, j)]).collect());
                }
            }
            let fb = Mat::from_fn(r.1 - r.0, cols.len(), |i, j| cols[j][i]);
            let bb = sub(&prob.b1, r, r);
            let ob = orthonormalise(&fb, bb.as_ref(), settings.rank_tolerance, "velocity")?;
            cols1.push((total, total + ob.ncols()));
            total += ob.ncols();
            blocks1.push((r, ob));
        }
        let mut phi1 = Mat::<f64>::zeros(n1, total);
        for ((r, ob), c) in blocks1.iter().zip(&cols1) {
            for j in 0..ob.ncols() {
                for i in 0..ob.nrows() {
                    phi1[(r.0 + i, c.0 + j)] = ob[(i, j)];
                }
            }
        }
        // Force fields: strain images B2⁻¹Dᵀφ1 per link, or the given force fields.
        if let Some(f2) = forces {
            if f2.nrows() != n2 {
                return Err(shape("forces", (n2, f2.ncols()), (f2.nrows(), f2.ncols())));
            }
        }
        let y = match forces {
            Some(f2) => f2.to_owned(),
            None => prob.b2.partial_piv_lu().solve(prob.d.transpose() * &phi1),
        };
        let mut phi2_blocks = Vec::new();
        let mut cols2 = Vec::new();
        let mut total2 = 0;
        for (b, beam) in layout.beams.iter().enumerate() {
            let r = (layout.x2_offset(b), layout.x2_offset(b) + k * beam.n_elements());
            let yb = match forces {
                Some(_) => sub(&y, r, (0, y.ncols())),
                None => sub(&y, r, cols1[b]),
            };
            let bb = sub(&prob.b2, r, r);
            let ob = orthonormalise(&yb, bb.as_ref(), settings.rank_tolerance.max(1e-12), "force")?;
            cols2.push((total2, total2 + ob.ncols()));
            total2 += ob.ncols();
            phi2_blocks.push((r, ob));
        }
        let mut phi2 = Mat::<f64>::zeros(n2, total2);
        for ((r, ob), c) in phi2_blocks.iter().zip(&cols2) {
            for j in 0..ob.ncols() {
                for i in 0..ob.nrows() {
                    phi2[(r.0 + i, c.0 + j)] = ob[(i, j)];
                }
            }
        }
        Ok(LinkBasis {
            layout,
            phi1,
            phi2,
            cols1,
            cols2,
            b1: prob.b1.clone(),
            b2: prob.b2.clone(),
            d: prob.d.clone(),
        })
    }

    /// Number of velocity fields `na`.
    pub fn n1(&self) -> usize {
        self.phi1.ncols()
    }

    /// Number of force fields `nb`.
    pub fn n2(&self) -> usize {
        self.phi2.ncols()
    }

    /// Velocity fields (`n1 × na`).
    pub fn phi1(&self) -> MatRef<'_, f64> {
        self.phi1.as_ref()
    }

    /// Force fields (`n2 × nb`).
    pub fn phi2(&self) -> MatRef<'_, f64> {
        self.phi2.as_ref()
    }

    /// Coordinates `Φ1ᵀB1 X1` of velocity fields `x1` (`n1 × c`).
    pub fn coordinates1(&self, x1: MatRef<'_, f64>) -> Mat<f64> {
        self.phi1.transpose() * (&self.b1 * x1)
    }

    /// Coordinates `Φ2ᵀB2 X2` of force fields `x2` (`n2 × c`).
    pub fn coordinates2(&self, x2: MatRef<'_, f64>) -> Mat<f64> {
        self.phi2.transpose() * (&self.b2 * x2)
    }
}

/// `Γ1`, `Γ2` of one link, dense (the link's fields couple only among themselves), laid out so
/// that every contraction is one matrix–vector product: `g1_lj[i + m(j + m l)] = Γ1^l_ij`,
/// `g2_lj[i + m(j + m2 l)] = g2_jl[i + m(l + m2 j)] = Γ2^l_ij`, and the symmetrised
/// `g1s[i + m(j + m l)] = Γ1^l_ij + Γ1^j_il`: with `M = Σ_l q_l (Γ1^l_ij + Γ1^j_il)`, the `Γ1`
/// term of `f1` is `−Σ_jl Γ1^l_ij q_j q_l = −½ M q` and its Jacobian `−M`, one pass over the
/// tensor for both. With `T = Σ_l q2_l Γ2^l` (from `g2_lj`) and `S[i, l] = Σ_j Γ2^l_ij q2_j`
/// (from `g2_jl`), `S q2 = T q2`, so the right-hand side's `Γ2` terms (`−T q2` in `f1`, `Tᵀq1`
/// in `f2`) read `g2_lj` only; `S` enters the Jacobian's `q2` columns `−(T + S)`.
#[derive(Clone, Debug)]
pub(crate) struct LinkTensors {
    /// First column and count of the link's velocity fields.
    c1: (usize, usize),
    /// First column and count of the link's force fields.
    c2: (usize, usize),
    g1_lj: Vec<f64>,
    g1s: Vec<f64>,
    g2_lj: Vec<f64>,
    g2_jl: Vec<f64>,
    /// `g2_t[j + m2(l + m2 i)] = Γ2^l_ij`: `K22 = Σ_i q1_i Γ2_i` as a matrix–vector product.
    g2_t: Vec<f64>,
}

/// The Galerkin operators on a [`LinkBasis`] (module docs).
#[derive(Clone, Debug)]
pub(crate) struct AmbientOps {
    pub w: Mat<f64>,
    pub sigma: Mat<f64>,
    links: Vec<LinkTensors>,
    /// `Σ` and `W` couple no two links (the FE operators are per beam): the Jacobian of
    /// `(f1, f2)` is block-diagonal by link.
    block_diagonal: bool,
    pub b_u: Mat<f64>,
}

impl AmbientOps {
    pub fn new(basis: &LinkBasis, damping: Option<&Mat<f64>>, inputs: &[Input]) -> Result<Self> {
        let layout = &basis.layout;
        let comps = layout.components;
        let k = comps.k();
        let (na, n1) = (basis.n1(), layout.n1());
        let phi1 = &basis.phi1;
        let phi2 = &basis.phi2;
        let w = phi1.transpose() * &basis.d * phi2;
        let sigma = match damping {
            Some(d) => {
                if d.nrows() != n1 || d.ncols() != n1 {
                    return Err(shape("damping operator", (n1, n1), (d.nrows(), d.ncols())));
                }
                let s = phi1.transpose() * d * phi1;
                Mat::from_fn(na, na, |i, j| 0.5 * (s[(i, j)] + s[(j, i)]))
            }
            None => Mat::zeros(na, na),
        };
        let b1phi = &basis.b1 * phi1;
        let b2phi = &basis.b2 * phi2;
        let emb = |mat: &Mat<f64>, i0: usize, j: usize| -> Vector6<f64> {
            let vals: Vec<f64> = (0..k).map(|c| mat[(i0 + c, j)]).collect();
            comps.embed(&vals)
        };
        let mut links = Vec::new();
        for (b, beam) in layout.beams.iter().enumerate() {
            let c1 = basis.cols1[b];
            let c2 = basis.cols2[b];
            let m = c1.1 - c1.0;
            let m2 = c2.1 - c2.0;
            let mut g1 = vec![0.0; m * m * m];
            let mut g2 = vec![0.0; m * m2 * m2];
            for n in 0..beam.n_nodes() {
                let i0 = layout.x1_index(b, n, 0);
                let p: Vec<Vector6<f64>> = (c1.0..c1.1).map(|j| emb(phi1, i0, j)).collect();
                let mp: Vec<Vector6<f64>> = (c1.0..c1.1).map(|j| emb(&b1phi, i0, j)).collect();
                for l in 0..m {
                    for j in 0..m {
                        let t = l1_times(&p[j], &mp[l]);
                        for i in 0..m {
                            g1[(l * m + i) * m + j] += p[i].dot(&t);
                        }
                    }
                }
            }
            for e in 0..beam.n_elements() {
                let i0 = layout.x2_index(b, e, 0);
                let (na_, nb_) = (layout.x1_index(b, e, 0), layout.x1_index(b, e + 1, 0));
                let bar: Vec<Vector6<f64>> =
                    (c1.0..c1.1).map(|j| (emb(phi1, na_, j) + emb(phi1, nb_, j)) * 0.5).collect();
                let p2: Vec<Vector6<f64>> = (c2.0..c2.1).map(|j| emb(phi2, i0, j)).collect();
                let cp2: Vec<Vector6<f64>> = (c2.0..c2.1).map(|j| emb(&b2phi, i0, j)).collect();
                for l in 0..m2 {
                    for j in 0..m2 {
                        let t = l2_times(&p2[j], &cp2[l]);
                        for i in 0..m {
                            g2[(l * m + i) * m2 + j] += bar[i].dot(&t);
                        }
                    }
                }
            }
            // re-layout (l, i, j) → both orders of the docs of `LinkTensors`
            let (mut g1_lj, mut g1s) = (vec![0.0; m * m * m], vec![0.0; m * m * m]);
            for l in 0..m {
                for i in 0..m {
                    for j in 0..m {
                        let v = g1[(l * m + i) * m + j];
                        g1_lj[i + m * (j + m * l)] = v;
                        g1s[i + m * (j + m * l)] = v + g1[(j * m + i) * m + l];
                    }
                }
            }
            let (mut g2_lj, mut g2_jl) = (vec![0.0; m * m2 * m2], vec![0.0; m * m2 * m2]);
            let mut g2_t = vec![0.0; m * m2 * m2];
            for l in 0..m2 {
                for i in 0..m {
                    for j in 0..m2 {
                        let v = g2[(l * m + i) * m2 + j];
                        g2_lj[i + m * (j + m2 * l)] = v;
                        g2_jl[i + m * (l + m2 * j)] = v;
                        g2_t[j + m2 * (l + m2 * i)] = v;
                    }
                }
            }
            links.push(LinkTensors {
                c1: (c1.0, m),
                c2: (c2.0, m2),
                g1_lj,
                g1s,
                g2_lj,
                g2_jl,
                g2_t,
            });
        }

        let mut b_u = Mat::<f64>::zeros(na, inputs.len());
        for (c, input) in inputs.iter().enumerate() {
            for &(idx, wgt) in &input.entries {
                if idx >= n1 {
                    return Err(invalid(
                        format!("input `{}` index", input.name),
                        idx,
                        format!("X1 has {n1} entries"),
                    ));
                }
                for i in 0..na {
                    b_u[(i, c)] += phi1[(idx, i)] * wgt;
                }
            }
        }
        let link_of =
            |cols: &[(usize, usize)], c: usize| cols.iter().position(|r| c >= r.0 && c < r.1);
        let block_diagonal = (0..na).all(|j| {
            (0..na).all(|i| {
                sigma[(i, j)] == 0.0 || link_of(&basis.cols1, i) == link_of(&basis.cols1, j)
            })
        }) && (0..w.ncols()).all(|j| {
            (0..na)
                .all(|i| w[(i, j)] == 0.0 || link_of(&basis.cols1, i) == link_of(&basis.cols2, j))
        });
        Ok(AmbientOps { w, sigma, links, block_diagonal, b_u })
    }

    /// `Σ q1 + W q2` into `f1`, `−Wᵀ q1` into `f2` and their (whole, dense) Jacobian into `jac`.
    fn dense_linear_terms(
        &self,
        q1: &[f64],
        q2: &[f64],
        f1: &mut [f64],
        f2: &mut [f64],
        jac: Option<&mut [f64]>,
    ) {
        let (na, nb) = (q1.len(), q2.len());
        let n = na + nb;
        for j in 0..na {
            let c = self.sigma.col_as_slice(j);
            let s = q1[j];
            f1.iter_mut().zip(c).for_each(|(f, a)| *f += s * a);
        }
        for j in 0..nb {
            let c = self.w.col_as_slice(j);
            let s = q2[j];
            f1.iter_mut().zip(c).for_each(|(f, a)| *f += s * a);
            f2[j] = -c.iter().zip(q1).map(|(a, q)| a * q).sum::<f64>();
        }
        if let Some(j) = jac {
            let j = &mut j[..n * n];
            j.fill(0.0);
            for c in 0..na {
                j[c * n..c * n + na].copy_from_slice(self.sigma.col_as_slice(c));
            }
            for c in 0..nb {
                let w = self.w.col_as_slice(c);
                j[(na + c) * n..(na + c) * n + na].copy_from_slice(w);
                for (r, wr) in w.iter().enumerate() {
                    j[r * n + na + c] = -wr;
                }
            }
        }
    }

    /// `(f1, f2)` at ambient coordinates `(q1, q2)` and input `u`, and with `jac` the dense
    /// Jacobian of `(f1, f2)` with respect to `(q1, q2)` (`(na + nb)²`, column-major). When the
    /// operators are block-diagonal by link ([`AmbientOps::link_blocks`]) only the link blocks
    /// of `jac` are written (entries outside them are zero and must be zero in `jac`: a buffer
    /// zeroed once and only ever passed here keeps them). `tmp`: scratch of
    /// [`AmbientOps::scratch_len`].
    #[allow(clippy::too_many_arguments)]
    pub fn eval(
        &self,
        q1: &[f64],
        q2: &[f64],
        u: &[f64],
        f1: &mut [f64],
        f2: &mut [f64],
        mut jac: Option<&mut [f64]>,
        tmp: &mut [f64],
    ) {
        let (na, nb) = (q1.len(), q2.len());
        let n = na + nb;
        f1.fill(0.0);
        f2.fill(0.0);
        if self.block_diagonal {
            // Σ q1 + W q2 and −Wᵀ q1 on the link blocks only (the rest of Σ, W is zero)
            for lt in &self.links {
                let ((o1, m), (o2, m2)) = (lt.c1, lt.c2);
                let f1b = &mut f1[o1..o1 + m];
                for j in 0..m {
                    let c = &self.sigma.col_as_slice(o1 + j)[o1..o1 + m];
                    let s = q1[o1 + j];
                    f1b.iter_mut().zip(c).for_each(|(f, a)| *f += s * a);
                }
                for j in 0..m2 {
                    let c = &self.w.col_as_slice(o2 + j)[o1..o1 + m];
                    let s = q2[o2 + j];
                    f1b.iter_mut().zip(c).for_each(|(f, a)| *f += s * a);
                    f2[o2 + j] = -c.iter().zip(&q1[o1..o1 + m]).map(|(a, q)| a * q).sum::<f64>();
                }
                // the Jacobian's link blocks are written whole with the `Γ` terms below
            }
        } else {
            self.dense_linear_terms(q1, q2, f1, f2, jac.as_deref_mut());
        }
        for (k, &uk) in u.iter().enumerate() {
            let c = self.b_u.col_as_slice(k);
            f1.iter_mut().zip(c).for_each(|(f, a)| *f += uk * a);
        }
        let mv = |out: &mut [f64], g: &[f64], rows: usize, x: &[f64]| {
            matvec(&mut out[..rows], false, g, x, 1.0);
        };
        for lt in &self.links {
            let ((o1, m), (o2, m2)) = (lt.c1, lt.c2);
            let (u1, rest) = tmp[..2 * m * m + 2 * m * m2 + m2 * m2].split_at_mut(m * m);
            let (_, rest) = rest.split_at_mut(m * m);
            let (t2, rest) = rest.split_at_mut(m * m2);
            let (s2, k22) = rest.split_at_mut(m * m2);
            let q1b = &q1[o1..o1 + m];
            let q2b = &q2[o2..o2 + m2];
            // Γ1: M[i, j] = Σ_l (Γ1^l_ij + Γ1^j_il) q_l, f1 −= ½ M q, J[·, j] −= M[·, j]
            mv(u1, &lt.g1s, m * m, q1b);
            gemv(&mut f1[o1..o1 + m], true, u1, m, q1b, -0.5);
            // Γ2: T[i, j] = Σ_l Γ2^l_ij q2_l; f1 −= T q2 (= S q2 with S[i, l] = Σ_j Γ2^l_ij q2_j),
            // f2 += Tᵀ q1
            mv(t2, &lt.g2_lj, m * m2, q2b);
            gemv(&mut f1[o1..o1 + m], true, t2, m, q2b, -1.0);
            gemv_t(&mut f2[o2..o2 + m2], true, t2, m, q1b, 1.0);
            let Some(jm) = jac.as_deref_mut() else { continue };
            // Γ2: S for the Jacobian's q2 columns −(T + S)
            mv(s2, &lt.g2_jl, m * m2, q2b);
            // Γ2: K22[j, l] = Σ_i Γ2^l_ij q1_i
            mv(k22, &lt.g2_t, m2 * m2, q1b);
            if self.block_diagonal {
                // the link blocks whole: [Σ − M, W − T − S; (T − W)ᵀ, K22]
                for c in 0..m {
                    let col = &mut jm[(o1 + c) * n + o1..(o1 + c) * n + o1 + m];
                    let sc = &self.sigma.col_as_slice(o1 + c)[o1..o1 + m];
                    col.iter_mut()
                        .zip(sc)
                        .zip(&u1[c * m..(c + 1) * m])
                        .for_each(|((x, s), a)| *x = s - a);
                }
                for c in 0..m2 {
                    let cc = na + o2 + c;
                    let w = &self.w.col_as_slice(o2 + c)[o1..o1 + m];
                    let (t, s) = (&t2[c * m..(c + 1) * m], &s2[c * m..(c + 1) * m]);
                    let col = &mut jm[cc * n + o1..cc * n + o1 + m];
                    for i in 0..m {
                        col[i] = w[i] - (t[i] + s[i]);
                    }
                    for i in 0..m {
                        jm[(o1 + i) * n + cc] = -w[i] + t[i];
                    }
                    jm[cc * n + na + o2..cc * n + na + o2 + m2]
                        .copy_from_slice(&k22[c * m2..(c + 1) * m2]);
                }
                continue;
            }
            for c in 0..m {
                let col = &mut jm[(o1 + c) * n + o1..(o1 + c) * n + o1 + m];
                col.iter_mut().zip(&u1[c * m..(c + 1) * m]).for_each(|(x, a)| *x -= a);
            }
            for c in 0..m2 {
                let cc = na + o2 + c;
                let col = &mut jm[cc * n + o1..cc * n + o1 + m];
                col.iter_mut()
                    .zip(&t2[c * m..(c + 1) * m])
                    .zip(&s2[c * m..(c + 1) * m])
                    .for_each(|((x, a), b)| *x -= a + b);
                for (i, t) in t2[c * m..(c + 1) * m].iter().enumerate() {
                    jm[(o1 + i) * n + cc] += t;
                }
                for (j, k) in k22[c * m2..(c + 1) * m2].iter().enumerate() {
                    jm[cc * n + na + o2 + j] += k;
                }
            }
        }
    }

    /// `((first velocity column, count), (first force column, count))` per link when the
    /// Jacobian of `(f1, f2)` is block-diagonal by link.
    pub fn link_blocks(
        &self,
    ) -> Option<impl Iterator<Item = ((usize, usize), (usize, usize))> + '_> {
        self.block_diagonal.then(|| self.links.iter().map(|l| (l.c1, l.c2)))
    }

    /// Per link: `((first velocity column, count), (first force column, count), Γ1, Γ2)` with
    /// `Γ1[i + m(j + m l)] = Γ1^l_ij`, `Γ2[i + m(j + m2 l)] = Γ2^l_ij` (link-local indices).
    pub(crate) fn link_gammas(&self) -> impl Iterator<Item = LinkGammas<'_>> + '_ {
        self.links.iter().map(|l| (l.c1, l.c2, &l.g1_lj[..], &l.g2_lj[..]))
    }

    /// What decides which entries of the ambient Jacobian [`AmbientOps::eval`] writes: whether
    /// it is block-diagonal by link, and the links' column ranges.
    pub(crate) fn layout_key(&self) -> impl Iterator<Item = usize> + '_ {
        std::iter::once(usize::from(self.block_diagonal))
            .chain(self.links.iter().flat_map(|l| [l.c1.0, l.c1.1, l.c2.0, l.c2.1]))
    }

    /// Scratch length [`AmbientOps::eval`] needs.
    pub fn scratch_len(&self) -> usize {
        self.links
            .iter()
            .map(|l| {
                let (m, m2) = (l.c1.1, l.c2.1);
                2 * m * m + 2 * m * m2 + m2 * m2
            })
            .max()
            .unwrap_or(0)
    }
}
