//! Export of the exact-joints reduced model (theory.md §10) to JSON metadata plus NumPy
//! `.npy` arrays, and the reader of the data.
//!
//! The directory holds `model.json` ([`ExactJointsMetadata`]: sizes, state layout, joints,
//! conventions, the list of arrays) and one `.npy` per array (little-endian `f64`, C order):
//! everything the right-hand side `ẋ = f(x, u)` of theory.md §10.4 needs, so that another tool
//! evaluates the same model:
//!
//! ```text
//!   A(ξ) = [S; C_j(ξ_j) E_j …],  C_j(ξ) = C_c + Σ_pq R_pq(ξ) C_pq,  R(ξ) = (ξ0² − |ξv|²)I + 2ξvξvᵀ + 2ξ0ξ̃v
//!   G = (AAᵀ)⁻¹, C0 = A Z0, H = G C0, S = I − C0ᵀH = LLᵀ, Z = (Z0 − AᵀH)L⁻ᵀ, W_r = H L⁻ᵀ
//!   q1 = Z p, q2 = Z2 p2, (f1, f2) the link Galerkin operators (theory.md §10.2)
//!   ω from the end-node rows E_j q1 (joint) and the root rows q1, ξ̇ as in §10.4
//!   V = Ȧ Z (joint rows, Ȧ_j = Σ_c ∂C_j/∂ξ_c ξ̇_c E_j), X = −(W_rᵀV + VᵀW_r) on the joint rows,
//!   K = −VᵀW_r − Φ(X)ᵀ, ṗ = Zᵀf1 − K p, ṗ2 = Z2ᵀ f2
//! ```
//!
//! The reader ([`read_exact_joints`]) returns the metadata and the arrays, checked against the
//! sizes of the metadata; the arrays are bit-for-bit those written.

use crate::error::{ModalError, Result};
use crate::exact_joints::ExactJointsRom;
use crate::export::ArrayInfo;
use crate::layout::Components;
use crate::npy::{self, NpyArray};
use faer::Mat;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Format name written in the exact-joints `model.json`.
pub const EXACT_JOINTS_FORMAT: &str = "flexmpc-exact-joints-rom";
/// Format version.
pub const EXACT_JOINTS_VERSION: u32 = 1;

/// One two-end joint of the exported model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExportedJoint {
    /// Joint name.
    pub name: String,
    /// Offset of its relative quaternion `ξ_j` in the state.
    pub offset: usize,
    /// Its first row in `A` (after the support rows and the earlier joints).
    pub row_offset: usize,
    /// Rows `r_j`.
    pub rows: usize,
    /// Reference relative rotation `ξ̄_j` (scalar first).
    pub reference: [f64; 4],
    /// `(beam, node)` of ends `a` and `b`.
    pub ends: [(usize, usize); 2],
    /// Array names of `E_j` (`2k × na`) and of `[C_c, C_00, C_01, …, C_22]` (`10 × r_j × 2k`).
    pub arrays: [String; 2],
}

/// The content of the exact-joints `model.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExactJointsMetadata {
    /// Always [`EXACT_JOINTS_FORMAT`].
    pub format: String,
    /// Always [`EXACT_JOINTS_VERSION`].
    pub version: u32,
    /// Planar or spatial components.
    pub components: Components,
    /// Components per node `k`.
    pub k: usize,
    /// Link velocity fields `na`.
    pub n_fields: usize,
    /// Link force fields `nb`.
    pub n_force_fields: usize,
    /// Reduced velocity coordinates `m` (`p`).
    pub n_p: usize,
    /// Reduced force coordinates `m2` (`p2`).
    pub n_p2: usize,
    /// Inputs.
    pub n_inputs: usize,
    /// State length.
    pub n_state: usize,
    /// Support rows `rs` (constant, the first rows of `A`).
    pub n_support_rows: usize,
    /// All rows `r`.
    pub n_rows: usize,
    /// Offset of the root quaternion `ξ_root`, when the state carries it.
    pub root_offset: Option<usize>,
    /// Two-end joints in state order.
    pub joints: Vec<ExportedJoint>,
    /// `(component c, rate axis a)`: `ω_a` is component `c` of a node's values.
    pub rate_components: Vec<(usize, usize)>,
    /// Input names (columns of `b_u`).
    pub inputs: Vec<String>,
    /// The reference state (at rest, reference rotations).
    pub reference_state: Vec<f64>,
    /// The equations and conventions, in words.
    pub conventions: Vec<String>,
    /// Arrays by name.
    pub arrays: BTreeMap<String, ArrayInfo>,
}

fn mat_array(m: &Mat<f64>) -> NpyArray {
    NpyArray {
        shape: vec![m.nrows(), m.ncols()],
        data: (0..m.nrows()).flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)])).collect(),
    }
}

/// `[l, i, j]` dense tensor (`nl × ni × nj`, C order) of per-link blocks stored as
/// `g[i + mi (j + mj l)]` (link-local) at offsets `(ol, oi, oj)`.
fn place(
    out: &mut [f64],
    dims: (usize, usize),
    g: &[f64],
    o: (usize, usize, usize),
    n: (usize, usize, usize),
) {
    let (ni, nj) = dims;
    let (ol, oi, oj) = o;
    let (ml, mi, mj) = n;
    for l in 0..ml {
        for j in 0..mj {
            for i in 0..mi {
                out[((ol + l) * ni + oi + i) * nj + oj + j] = g[i + mi * (j + mj * l)];
            }
        }
    }
}

impl ExactJointsRom {
    /// Writes the model to directory `dir` (created if needed); see the module docs.
    pub fn export(&self, dir: &Path) -> Result<ExactJointsMetadata> {
        std::fs::create_dir_all(dir)
            .map_err(|e| ModalError::Io { path: dir.display().to_string(), source: e })?;
        let (ops, cons, z0, z2, rate_comps) = self.parts();
        let basis = self.basis();
        let layout = &basis.layout;
        let k = layout.k();
        let (na, nb, nu) = (basis.n1(), basis.n2(), self.n_inputs());
        let mut gamma1 = vec![0.0; na * na * na];
        let mut gamma2 = vec![0.0; nb * na * nb];
        for ((o1, m), (o2, m2), g1, g2) in ops.link_gammas() {
            place(&mut gamma1, (na, na), g1, (o1, o1, o1), (m, m, m));
            place(&mut gamma2, (na, nb), g2, (o2, o1, o2), (m2, m, m2));
        }
        let mut arrays: Vec<(String, NpyArray, String)> = vec![
            ("sigma".into(), mat_array(&ops.sigma), "damping Σ = Φ1ᵀD_dampΦ1 (na × na)".into()),
            ("w".into(), mat_array(&ops.w), "W = Φ1ᵀDΦ2 (na × nb)".into()),
            ("b_u".into(), mat_array(&ops.b_u), "input matrix B_u (na × inputs)".into()),
            (
                "gamma1".into(),
                NpyArray { shape: vec![na, na, na], data: gamma1 },
                "Γ1[l, i, j] = ⟨φ1i, L1(φ1j) M φ1l⟩ on the link fields (na × na × na)".into(),
            ),
            (
                "gamma2".into(),
                NpyArray { shape: vec![nb, na, nb], data: gamma2 },
                "Γ2[l, i, j] = ⟨φ1i, L2(φ2j) C φ2l⟩; l, j over force fields (nb × na × nb)".into(),
            ),
            (
                "support".into(),
                mat_array(&cons.support),
                "support rows S (rs × na), constant".into(),
            ),
            ("z0".into(), mat_array(z0), "Z0 (na × m), orthonormal, A(ξ̄) Z0 = 0".into()),
            ("z2".into(), mat_array(z2), "Z2 (nb × m2), orthonormal: q2 = Z2 p2".into()),
            ("phi1".into(), mat_array(&basis.phi1), "link velocity fields Φ1 (n1 × na)".into()),
            ("phi2".into(), mat_array(&basis.phi2), "link force fields Φ2 (n2 × nb)".into()),
        ];
        if let Some((b, n, _)) = cons.root {
            let rows = Mat::from_fn(k, na, |i, c| basis.phi1[(layout.x1_index(b, n, i), c)]);
            arrays.push((
                "root_rows".into(),
                mat_array(&rows),
                "the fields' values at the supported node (k × na): ω_root from them".into(),
            ));
        }
        let mut joints = Vec::new();
        let mut row = cons.support.nrows();
        for (j, jr) in cons.joints.iter().enumerate() {
            let kk = jr.e.nrows();
            let r = jr.rows;
            let mut c = Vec::with_capacity(10 * r * kk);
            for t in std::iter::once(&jr.c_c).chain(jr.c_pq.iter()) {
                c.extend((0..r).flat_map(|i| (0..kk).map(move |col| t[col * r + i])));
            }
            let names = [format!("joint{j}_e"), format!("joint{j}_c")];
            arrays.push((
                names[0].clone(),
                mat_array(&jr.e),
                format!("E of joint `{}`: fields' values at ends a, b (2k × na)", jr.name),
            ));
            arrays.push((
                names[1].clone(),
                NpyArray { shape: vec![10, r, kk], data: c },
                format!(
                    "[C_c, C_pq (index 1 + 3p + q)] of joint `{}` (10 × r_j × 2k): C(ξ) = C_c + Σ R_pq(ξ) C_pq",
                    jr.name
                ),
            ));
            joints.push(ExportedJoint {
                name: jr.name.clone(),
                offset: self.joint_offset(j),
                row_offset: row,
                rows: r,
                reference: [jr.reference[0], jr.reference[1], jr.reference[2], jr.reference[3]],
                ends: jr.ends,
                arrays: names,
            });
            row += r;
        }
        let infos = crate::export::write_arrays(dir, &arrays)?;
        let meta = ExactJointsMetadata {
            format: EXACT_JOINTS_FORMAT.into(),
            version: EXACT_JOINTS_VERSION,
            components: layout.components,
            k,
            n_fields: na,
            n_force_fields: nb,
            n_p: self.n_p(),
            n_p2: self.n_p2(),
            n_inputs: nu,
            n_state: self.n_state(),
            n_support_rows: cons.support.nrows(),
            n_rows: row,
            root_offset: self.has_root().then(|| self.root_offset()),
            joints,
            rate_components: rate_comps.to_vec(),
            inputs: self.input_names().to_vec(),
            reference_state: self.reference_state(),
            conventions: vec![
                "state x = [p (n_p), p2 (n_p2), xi_root (4, if root_offset), xi_j (4 per joint)], quaternions scalar first".into(),
                "R(xi) = (xi0^2 - |xiv|^2) I + 2 xiv xiv^T + 2 xi0 skew(xiv) (homogeneous eq. 9); C_j = C_c + sum_pq R_pq C_pq; A = [support; C_j E_j ...]".into(),
                "G = inv(A A^T); C0 = A z0; H = G C0; S = I - C0^T H = L L^T (Cholesky, L lower); Z = (z0 - A^T H) L^-T; W_r = H L^-T".into(),
                "q1 = Z p, q2 = z2 p2; f1 = sigma q1 + w q2 - sum_l q1_l gamma1[l] q1 - sum_l q2_l gamma2[l] q2 + b_u u; f2 = -w^T q1 + sum_l q2_l gamma2[l]^T q1".into(),
                "node rates: omega[axis] = values[end * k + c] for (c, axis) in rate_components, values = joint E_j q1 (end a = 0, b = 1) or root_rows q1".into(),
                "xi_root' = U(omega_root) xi_root; xi_j' = U(omega_b) xi_j - Ubar(omega_a) xi_j; U(w) xi = 1/2 xi (x) (0, w), Ubar(w) xi = 1/2 (0, w) (x) xi".into(),
                "V = Adot Z on the joint rows, Adot_j = (sum_c dC_j/dxi_c xi_j'_c) E_j; X = -(W_r^T V + V^T W_r) (W_r on the joint rows); Lambda = tril(X) with half its diagonal; K = -V^T W_r - Lambda^T".into(),
                "p' = Z^T f1 - K p; p2' = z2^T f2 (theory.md §10.4)".into(),
            ],
            arrays: infos,
        };
        crate::export::write_metadata(dir, &meta)?;
        Ok(meta)
    }
}

/// Reads the data written by [`ExactJointsRom::export`]: the metadata and every listed array,
/// each checked against the shape the metadata's sizes give.
pub fn read_exact_joints(dir: &Path) -> Result<(ExactJointsMetadata, BTreeMap<String, NpyArray>)> {
    let (meta, path): (ExactJointsMetadata, String) = crate::export::read_metadata(dir)?;
    let bad = |reason: String| ModalError::Format { path: path.clone(), reason };
    if meta.format != EXACT_JOINTS_FORMAT || meta.version != EXACT_JOINTS_VERSION {
        return Err(bad(format!(
            "format {} v{} is not {EXACT_JOINTS_FORMAT} v{EXACT_JOINTS_VERSION}",
            meta.format, meta.version
        )));
    }
    let (na, nb, k) = (meta.n_fields, meta.n_force_fields, meta.k);
    let rows: usize = meta.n_support_rows + meta.joints.iter().map(|j| j.rows).sum::<usize>();
    let state = meta.n_p
        + meta.n_p2
        + if meta.root_offset.is_some() { 4 } else { 0 }
        + 4 * meta.joints.len();
    if rows != meta.n_rows
        || state != meta.n_state
        || meta.reference_state.len() != state
        || meta.inputs.len() != meta.n_inputs
    {
        return Err(bad("inconsistent sizes in metadata".into()));
    }
    let mut expected: Vec<(String, Vec<usize>)> = vec![
        ("sigma".into(), vec![na, na]),
        ("w".into(), vec![na, nb]),
        ("b_u".into(), vec![na, meta.n_inputs]),
        ("gamma1".into(), vec![na, na, na]),
        ("gamma2".into(), vec![nb, na, nb]),
        ("support".into(), vec![meta.n_support_rows, na]),
        ("z0".into(), vec![na, meta.n_p]),
        ("z2".into(), vec![nb, meta.n_p2]),
    ];
    if meta.root_offset.is_some() {
        expected.push(("root_rows".into(), vec![k, na]));
    }
    for j in &meta.joints {
        expected.push((j.arrays[0].clone(), vec![2 * k, na]));
        expected.push((j.arrays[1].clone(), vec![10, j.rows, 2 * k]));
    }
    let mut out = BTreeMap::new();
    for (name, shape) in expected {
        let info =
            meta.arrays.get(&name).ok_or_else(|| bad(format!("array `{name}` is not listed")))?;
        let a = npy::read(&dir.join(&info.file))?;
        if a.shape != shape {
            return Err(bad(format!("array `{name}` has shape {:?}, expected {shape:?}", a.shape)));
        }
        out.insert(name, a);
    }
    for (name, info) in &meta.arrays {
        if !out.contains_key(name) {
            out.insert(name.clone(), npy::read(&dir.join(&info.file))?);
        }
    }
    Ok((meta, out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::ModeSelection;
    use crate::exact_joints::{from_fields, LinkBasisSettings};
    use crate::samples;
    use crate::{BasisSettings, StructureModel};
    use intrinsic_beam::Section;
    use nalgebra::Vector4;

    /// The 3D two-link (4 elements per link) on rigid link motions + 2 elastic modes, damped.
    fn model() -> ExactJointsRom {
        let s = multibody_constraints::samples::paper_3d(Section::paper_3d(), 4, 0.0).unwrap();
        let m = StructureModel::new(&s).unwrap();
        let b = m.modes(&BasisSettings::default()).unwrap();
        let sel = b.select(&ModeSelection::Lowest(b.n_rigid() + 2)).unwrap();
        let inputs = samples::inputs_3d(&s, &m).unwrap();
        let settings = LinkBasisSettings::default();
        from_fields(&s, &m, &[sel.phi1()], &settings, Some(&m.damping), &inputs).unwrap()
    }

    fn at(a: &NpyArray, i: usize, j: usize) -> f64 {
        a.data[i * a.shape[1] + j]
    }

    fn rotation(xi: &[f64; 4]) -> [[f64; 3]; 3] {
        let (w, v) = (xi[0], [xi[1], xi[2], xi[3]]);
        let vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        let sk = [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]];
        let mut r = [[0.0; 3]; 3];
        for p in 0..3 {
            for q in 0..3 {
                r[p][q] =
                    if p == q { w * w - vv } else { 0.0 } + 2.0 * v[p] * v[q] + 2.0 * w * sk[p][q];
            }
        }
        r
    }

    /// `A_j(ξ) = C_j(ξ) E_j` from the exported arrays.
    fn joint_rows(c: &NpyArray, e: &NpyArray, xi: &[f64; 4]) -> Vec<Vec<f64>> {
        let (r, kk, na) = (c.shape[1], c.shape[2], e.shape[1]);
        let rot = rotation(xi);
        let coef = |i: usize, col: usize| {
            let mut v = c.data[i * kk + col];
            for p in 0..3 {
                for q in 0..3 {
                    v += rot[p][q] * c.data[((1 + 3 * p + q) * r + i) * kk + col];
                }
            }
            v
        };
        (0..r)
            .map(|i| {
                (0..na).map(|f| (0..kk).map(|col| coef(i, col) * at(e, col, f)).sum()).collect()
            })
            .collect()
    }

    #[test]
    fn export_reads_back_with_the_model_values() {
        let rom = model();
        let dir = std::env::temp_dir().join(format!("modal-rom-ej-export-{}", std::process::id()));
        let meta = rom.export(&dir).unwrap();
        let (back, arrays) = read_exact_joints(&dir).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(meta, back);
        let (ops, cons, z0, z2, _) = rom.parts();
        let (na, nb) = (rom.basis().n1(), rom.basis().n2());
        assert_eq!((back.n_p, back.n_p2, back.n_state), (rom.n_p(), rom.n_p2(), rom.n_state()));
        assert_eq!(back.joints.len(), rom.n_joints());
        assert_eq!(back.root_offset, Some(rom.root_offset()));
        for (name, m) in
            [("sigma", &ops.sigma), ("w", &ops.w), ("b_u", &ops.b_u), ("z0", z0), ("z2", z2)]
        {
            let a = &arrays[name];
            assert_eq!(a.shape, vec![m.nrows(), m.ncols()], "{name}");
            for i in 0..m.nrows() {
                for j in 0..m.ncols() {
                    assert_eq!(at(a, i, j).to_bits(), m[(i, j)].to_bits(), "{name}[{i}, {j}]");
                }
            }
        }
        assert_eq!(arrays["gamma1"].shape, vec![na, na, na]);
        assert_eq!(arrays["gamma2"].shape, vec![nb, na, nb]);
        // the ambient right-hand side from the exported operators equals the model's
        let q1: Vec<f64> = (0..na).map(|i| (0.7 * i as f64 + 0.2).sin()).collect();
        let q2: Vec<f64> = (0..nb).map(|i| (1.3 * i as f64 - 0.4).cos()).collect();
        let u: Vec<f64> = (0..rom.n_inputs()).map(|i| 0.5 - 0.3 * i as f64).collect();
        let (mut f1, mut f2) = (vec![0.0; na], vec![0.0; nb]);
        let mut tmp = vec![0.0; ops.scratch_len()];
        ops.eval(&q1, &q2, &u, &mut f1, &mut f2, None, &mut tmp);
        let (g1, g2) = (&arrays["gamma1"].data, &arrays["gamma2"].data);
        let mut scale = 0.0f64;
        let mut err = 0.0f64;
        for i in 0..na {
            let mut v: f64 = (0..na).map(|j| ops.sigma[(i, j)] * q1[j]).sum::<f64>()
                + (0..nb).map(|j| ops.w[(i, j)] * q2[j]).sum::<f64>()
                + (0..u.len()).map(|c| ops.b_u[(i, c)] * u[c]).sum::<f64>();
            for l in 0..na {
                v -= q1[l] * (0..na).map(|j| g1[(l * na + i) * na + j] * q1[j]).sum::<f64>();
            }
            for l in 0..nb {
                v -= q2[l] * (0..nb).map(|j| g2[(l * na + i) * nb + j] * q2[j]).sum::<f64>();
            }
            err = err.max((v - f1[i]).abs());
            scale = scale.max(f1[i].abs());
        }
        for j in 0..nb {
            let mut v: f64 = -(0..na).map(|i| ops.w[(i, j)] * q1[i]).sum::<f64>();
            for l in 0..nb {
                v += q2[l] * (0..na).map(|i| g2[(l * na + i) * nb + j] * q1[i]).sum::<f64>();
            }
            err = err.max((v - f2[j]).abs());
            scale = scale.max(f2[j].abs());
        }
        assert!(scale > 0.0 && err <= 1e-12 * scale, "ambient rhs {err:e} of {scale:e}");
        // the joint rows from the exported coefficients: those of the model at a rotation away
        // from the reference, and annihilating Z0 at the reference
        for (j, info) in back.joints.iter().enumerate() {
            let (e, c) = (&arrays[&info.arrays[0]], &arrays[&info.arrays[1]]);
            let xi = Vector4::new(0.8, 0.3, -0.4, 0.2).normalize();
            let direct = cons.joints[j].rows_at(&xi);
            let rows = joint_rows(c, e, &[xi[0], xi[1], xi[2], xi[3]]);
            let big = rows.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
            for (i, row) in rows.iter().enumerate() {
                for (f, v) in row.iter().enumerate() {
                    assert!((v - direct[(i, f)]).abs() <= 1e-13 * big, "joint {j} row {i}");
                }
            }
            let rows0 = joint_rows(c, e, &info.reference);
            let z = &arrays["z0"];
            for row in &rows0 {
                for col in 0..back.n_p {
                    let v: f64 = (0..na).map(|f| row[f] * at(z, f, col)).sum();
                    assert!(v.abs() <= 1e-10 * big, "A(ξ̄) Z0 = {v:e}");
                }
            }
        }
        // a listed array missing is an error naming it
        let dir = std::env::temp_dir().join(format!("modal-rom-ej-bad-{}", std::process::id()));
        rom.export(&dir).unwrap();
        std::fs::remove_file(dir.join("z0.npy")).unwrap();
        let err = read_exact_joints(&dir).unwrap_err().to_string();
        let _ = std::fs::remove_dir_all(&dir);
        assert!(err.contains("z0"), "{err}");
    }
}
