//! Export of a modal model to JSON metadata plus NumPy `.npy` arrays, and the reader.
//!
//! A directory holds `model.json` (format, sizes, labels, conventions, layout and the list
//! of arrays with their shapes and meaning) and one `.npy` file per array (little-endian
//! `f64`, C order). Python: `np.load(dir + "/gamma1.npy")`; MATLAB: any `.npy` reader.
//! Reading returns a model whose arrays are bit-for-bit those written.

use crate::basis::ModeKind;
use crate::error::{ModalError, Result};
use crate::layout::{Components, Layout};
use crate::npy::{self, NpyArray};
use crate::rom::{ModalRom, QuaternionModel, RomOptions};
use crate::tensor::SparseTensor3;
use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

mod exact_joints;
pub use exact_joints::{
    read_exact_joints, ExactJointsMetadata, ExportedJoint, EXACT_JOINTS_FORMAT,
    EXACT_JOINTS_VERSION,
};

/// Format name written in `model.json`.
pub const FORMAT: &str = "flexmpc-modal-rom";
/// Format version.
pub const VERSION: u32 = 1;

/// One array's entry in the metadata.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArrayInfo {
    /// File name in the directory.
    pub file: String,
    /// Shape.
    pub shape: Vec<usize>,
    /// What it holds and how it is indexed.
    pub meaning: String,
}

/// The content of `model.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metadata {
    /// Always [`FORMAT`].
    pub format: String,
    /// Always [`VERSION`].
    pub version: u32,
    /// Planar or spatial components.
    pub components: Components,
    /// Velocity modes `m`.
    pub n_modes: usize,
    /// Rigid modes (the first ones).
    pub n_rigid: usize,
    /// `q2` coordinates.
    pub n_q2: usize,
    /// Quaternion coordinates.
    pub n_xi: usize,
    /// Inputs.
    pub n_inputs: usize,
    /// State length `m + n_q2 + n_xi`.
    pub n_state: usize,
    /// Frequencies (rad/s), also in `omega.npy`.
    pub frequencies_rad_s: Vec<f64>,
    /// Mode labels.
    pub labels: Vec<String>,
    /// Mode kinds.
    pub kinds: Vec<ModeKind>,
    /// Mode index of each `q2` coordinate.
    pub q2_modes: Vec<usize>,
    /// Kept quaternion modes (0 = `ξ̄`, `j+1` = from velocity mode `j`), if carried.
    pub quaternion_modes: Option<Vec<usize>>,
    /// Input names (columns of `b_u`).
    pub inputs: Vec<String>,
    /// Options the model was built with.
    pub options: RomOptions,
    /// Beam layout and reference configuration.
    pub layout: Layout,
    /// The equations and conventions, in words.
    pub conventions: Vec<String>,
    /// Arrays by name.
    pub arrays: BTreeMap<String, ArrayInfo>,
}

/// Writes `meta` to `dir/model.json`.
pub(crate) fn write_metadata<T: Serialize>(dir: &Path, meta: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(meta)
        .map_err(|e| ModalError::Format { path: "model.json".into(), reason: e.to_string() })?;
    let path = dir.join("model.json");
    std::fs::write(&path, text)
        .map_err(|e| ModalError::Io { path: path.display().to_string(), source: e })
}

/// Reads `dir/model.json` as `T`; returns it with the file's path, which names every error.
pub(crate) fn read_metadata<T: serde::de::DeserializeOwned>(dir: &Path) -> Result<(T, String)> {
    let path = dir.join("model.json");
    let shown = path.display().to_string();
    let text = std::fs::read_to_string(&path)
        .map_err(|e| ModalError::Io { path: shown.clone(), source: e })?;
    let meta = serde_json::from_str(&text)
        .map_err(|e| ModalError::Format { path: shown.clone(), reason: e.to_string() })?;
    Ok((meta, shown))
}

/// Writes each `(name, array, meaning)` to `dir/name.npy` and returns the metadata entries
/// that describe them.
pub(crate) fn write_arrays<N: AsRef<str>>(
    dir: &Path,
    arrays: &[(N, NpyArray, String)],
) -> Result<BTreeMap<String, ArrayInfo>> {
    let mut infos = BTreeMap::new();
    for (name, a, meaning) in arrays {
        let name = name.as_ref();
        let file = format!("{name}.npy");
        npy::write(&dir.join(&file), a)?;
        infos.insert(
            name.to_string(),
            ArrayInfo { file, shape: a.shape.clone(), meaning: meaning.clone() },
        );
    }
    Ok(infos)
}

fn mat_array(m: &Mat<f64>) -> NpyArray {
    NpyArray {
        shape: vec![m.nrows(), m.ncols()],
        data: (0..m.nrows()).flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)])).collect(),
    }
}

fn array_mat(a: &NpyArray) -> Mat<f64> {
    let (r, c) = (a.shape[0], a.shape[1]);
    Mat::from_fn(r, c, |i, j| a.data[i * c + j])
}

fn tensor_array(t: &SparseTensor3) -> NpyArray {
    NpyArray { shape: vec![t.dims.2, t.dims.0, t.dims.1], data: t.to_dense() }
}

fn array_tensor(a: &NpyArray) -> SparseTensor3 {
    let dims = (a.shape[1], a.shape[2], a.shape[0]);
    SparseTensor3::from_dense(dims, &a.data, 0.0)
}

impl ModalRom {
    /// Writes the model to directory `dir` (created if needed).
    pub fn export(&self, dir: &Path) -> Result<Metadata> {
        std::fs::create_dir_all(dir)
            .map_err(|e| ModalError::Io { path: dir.display().to_string(), source: e })?;
        let (m, nq2) = (self.n_modes(), self.n_q2());
        let mut arrays: Vec<(&str, NpyArray, String)> = vec![
            (
                "omega",
                NpyArray { shape: vec![m], data: self.omega.clone() },
                "frequencies Ω (rad/s), rigid modes 0".into(),
            ),
            ("sigma", mat_array(&self.sigma), "damping matrix Σ (m×m), eq. 16".into()),
            (
                "gamma1",
                tensor_array(&self.gamma1),
                "Γ1[l, i, j] = ⟨φ1i, L1(φ1j) M φ1l⟩, eq. 18 (m×m×m)".into(),
            ),
            (
                "gamma2",
                tensor_array(&self.gamma2),
                "Γ2[l, i, j] = ⟨φ1i, L2(φ2j) C φ2l⟩, eq. 19; j, l over q2 coordinates".into(),
            ),
            ("b_u", mat_array(&self.b_u), "input matrix B_u (m × inputs): η = B_u u".into()),
            (
                "phi1",
                mat_array(&self.phi1),
                "velocity modes at nodes (n1 × m), beams concatenated, k components per node"
                    .into(),
            ),
            ("phi2", mat_array(&self.phi2), "force modes at elements (n2 × m)".into()),
            ("proj1", mat_array(&self.proj1), "q1 = proj1 · x1 (m × n1)".into()),
            ("proj2", mat_array(&self.proj2), format!("q2 = proj2 · x2 ({nq2} × n2)")),
            (
                "compliance",
                NpyArray {
                    shape: vec![self.compliance.len(), self.layout.k(), self.layout.k()],
                    data: self.compliance.iter().flatten().copied().collect(),
                },
                "per-beam compliance C (k×k) for strains".into(),
            ),
        ];
        if let Some(q) = &self.quaternion {
            arrays.push(("a_xi", mat_array(&q.a_xi), "Aξ = ⟨φξi, φξj⟩, eq. 27".into()));
            arrays.push(("gamma_xi", tensor_array(&q.gamma_xi), "Γξ[l, i, j] = ⟨φξi, U(φωj) φξl⟩, eq. 28; i, l over kept quaternion modes, j over m".into()));
            arrays.push((
                "phi_xi",
                mat_array(&q.phi_xi),
                "quaternion modes at nodes (4·nodes × nξ)".into(),
            ));
            arrays.push((
                "xi_weights",
                NpyArray { shape: vec![q.weights.len()], data: q.weights.clone() },
                "node weights w_n of the quaternion products".into(),
            ));
        }
        let infos = write_arrays(dir, &arrays)?;
        let meta = Metadata {
            format: FORMAT.into(),
            version: VERSION,
            components: self.layout.components,
            n_modes: m,
            n_rigid: self.n_rigid,
            n_q2: nq2,
            n_xi: self.n_xi(),
            n_inputs: self.n_inputs(),
            n_state: self.n_state(),
            frequencies_rad_s: self.omega.clone(),
            labels: self.kinds.iter().map(|k| k.label(self.layout.components).to_string()).collect(),
            kinds: self.kinds.clone(),
            q2_modes: self.q2_modes.clone(),
            quaternion_modes: self.quaternion.as_ref().map(|q| q.kept.clone()),
            inputs: self.inputs.clone(),
            options: self.options.clone(),
            layout: self.layout.clone(),
            conventions: vec![
                "state q = [q1 (n_modes), q2 (n_q2), qxi (n_xi)]".into(),
                "dq1/dt = sigma q1 + Omega q2 - sum_l q1_l Gamma1[l] q1 - sum_l q2_l Gamma2[l] q2 + b_u u (eqs. 14-17)".into(),
                "dq2/dt = -Omega q1 + sum_l q2_l Gamma2[l]^T q1 (Omega, Gamma2 restricted to q2_modes)".into(),
                "dqxi/dt = inv(a_xi) sum_l qxi_l Gamma_xi[l] q1 (eqs. 26-29)".into(),
                "phi2 = +B2^-1 D^T phi1 / omega (paper's sign, eq. 15)".into(),
                "U(a) = 1/2 [[0, -a^T], [a, -skew(a)]] with the 1/2 of eq. 8; phi_xi_j = U_omega(xibar) phi_omega_j".into(),
                "components: planar k=3 [v1, v3, w2 | f1, f3, m2]; spatial k=6".into(),
            ],
            arrays: infos,
        };
        write_metadata(dir, &meta)?;
        Ok(meta)
    }

    /// Reads a model written by [`ModalRom::export`].
    pub fn read(dir: &Path) -> Result<ModalRom> {
        let (meta, path): (Metadata, String) = read_metadata(dir)?;
        let bad = |reason: String| ModalError::Format { path: path.clone(), reason };
        if meta.format != FORMAT || meta.version != VERSION {
            return Err(bad(format!(
                "format {} v{} is not {FORMAT} v{VERSION}",
                meta.format, meta.version
            )));
        }
        meta.layout.validate()?;
        let load = |name: &str, shape: Vec<usize>| -> Result<NpyArray> {
            let info = meta
                .arrays
                .get(name)
                .ok_or_else(|| bad(format!("array `{name}` is not listed")))?;
            let a = npy::read(&dir.join(&info.file))?;
            if a.shape != shape {
                return Err(bad(format!(
                    "array `{name}` has shape {:?}, expected {shape:?}",
                    a.shape
                )));
            }
            Ok(a)
        };
        let (m, nq2, k) = (meta.n_modes, meta.n_q2, meta.layout.k());
        let (n1, n2) = (meta.layout.n1(), meta.layout.n2());
        if meta.kinds.len() != m || meta.q2_modes.len() != nq2 || meta.inputs.len() != meta.n_inputs
        {
            return Err(bad("inconsistent sizes in metadata".into()));
        }
        let omega = load("omega", vec![m])?.data;
        let sigma = array_mat(&load("sigma", vec![m, m])?);
        let gamma1 = array_tensor(&load("gamma1", vec![m, m, m])?);
        let gamma2 = array_tensor(&load("gamma2", vec![nq2, m, nq2])?);
        let b_u = array_mat(&load("b_u", vec![m, meta.n_inputs])?);
        let phi1 = array_mat(&load("phi1", vec![n1, m])?);
        let phi2 = array_mat(&load("phi2", vec![n2, m])?);
        let proj1 = array_mat(&load("proj1", vec![m, n1])?);
        let proj2 = array_mat(&load("proj2", vec![nq2, n2])?);
        let nb = meta.layout.beams.len();
        let comp = load("compliance", vec![nb, k, k])?;
        let compliance = comp.data.chunks(k * k).map(|c| c.to_vec()).collect();
        let quaternion = match &meta.quaternion_modes {
            None => None,
            Some(kept) => {
                let nx = kept.len();
                let nodes = meta.layout.n_nodes_total();
                let a_xi = array_mat(&load("a_xi", vec![nx, nx])?);
                let gx = load("gamma_xi", vec![nx, nx, m])?;
                let gamma_xi = array_tensor(&gx);
                let phi_xi = array_mat(&load("phi_xi", vec![4 * nodes, nx])?);
                let weights = load("xi_weights", vec![nodes])?.data;
                let llt = a_xi.llt(Side::Lower).map_err(|e| ModalError::Numerical {
                    stage: "Cholesky of Aξ".into(),
                    reason: format!("{e:?}"),
                })?;
                let a_xi_inv = llt.inverse();
                let gamma_xi_scaled = crate::rom::scale_gamma_xi(&a_xi_inv, &gx.data, nx, m);
                Some(QuaternionModel {
                    kept: kept.clone(),
                    a_xi,
                    a_xi_inv,
                    gamma_xi,
                    gamma_xi_scaled,
                    phi_xi,
                    weights,
                })
            }
        };
        if meta.n_xi != quaternion.as_ref().map_or(0, |q: &QuaternionModel| q.kept.len()) {
            return Err(bad("n_xi does not match the quaternion modes".into()));
        }
        Ok(ModalRom {
            layout: meta.layout,
            options: meta.options,
            kinds: meta.kinds,
            n_rigid: meta.n_rigid,
            omega,
            sigma,
            gamma1,
            gamma2,
            q2_modes: meta.q2_modes,
            b_u,
            inputs: meta.inputs,
            phi1,
            phi2,
            proj1,
            proj2,
            compliance,
            quaternion,
        })
    }
}
