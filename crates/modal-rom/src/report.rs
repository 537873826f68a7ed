//! Frequencies, labels and mode shapes of a structure, for the `flexmpc modes` subcommand
//! (text, `--json`, and plots in the style of the paper's Figs. 4–5).

use crate::basis::{BasisSettings, ModalBasis};
use crate::error::{invalid, Result};
use crate::layout::Layout;
use crate::structure::StructureModel;
use intrinsic_beam::rotation::rotation;
use multibody_constraints::Structure;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// One beam's part of a velocity mode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BeamShape {
    /// Beam name.
    pub name: String,
    /// Arc length `s` of each node.
    pub s: Vec<f64>,
    /// Reference node positions (global).
    pub reference: Vec<[f64; 3]>,
    /// `φ1` at each node, local components (`k` values: planar `v1, v3, ω2`).
    pub phi1: Vec<Vec<f64>>,
    /// Translational velocity of the mode in the global frame, `T̄ φv`, at each node
    /// (the arrows of Fig. 5).
    pub velocity_global: Vec<[f64; 3]>,
}

/// One mode: frequency, label and shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModeShape {
    /// Mode index (rigid first, then by frequency).
    pub index: usize,
    /// Frequency (rad/s).
    pub frequency_rad_s: f64,
    /// Label.
    pub label: String,
    /// Per-beam shape.
    pub beams: Vec<BeamShape>,
}

/// What `flexmpc modes` prints: `--json` serialises this object.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModeReport {
    /// Frequencies (rad/s) of the first modes, rigid included, in order.
    pub frequencies_rad_s: Vec<f64>,
    /// Their labels (`rigid`, `axial`, `bending`/`bending-e2`/`bending-e3`, `torsion`, `mixed`).
    pub labels: Vec<String>,
    /// Number of rigid modes of the structure.
    pub n_rigid: usize,
    /// Mode shapes for plots.
    pub shapes: Vec<ModeShape>,
}

/// The first `n_modes` constrained modes of `structure` (at its reference configuration:
/// build it at the wanted joint angle), with labels and shapes.
pub fn mode_report(
    structure: &Structure,
    n_modes: usize,
    settings: &BasisSettings,
) -> Result<ModeReport> {
    let model = StructureModel::new(structure)?;
    let basis = model.modes(settings)?;
    report_of(&basis, n_modes)
}

/// The report of the first `n_modes` modes of a basis.
pub fn report_of(basis: &ModalBasis, n_modes: usize) -> Result<ModeReport> {
    if n_modes == 0 || n_modes > basis.n_modes() {
        return Err(invalid("n_modes", n_modes, format!("must lie in 1..={}", basis.n_modes())));
    }
    let labels = basis.labels();
    Ok(report_from_parts(
        basis.layout(),
        &basis.omega()[..n_modes],
        &labels[..n_modes],
        basis.n_rigid(),
        |j, b, n| basis.phi1_at(j, b, n),
    ))
}

/// The report of modes given by their frequencies, labels and `φ1` at `(mode, beam, node)`.
pub(crate) fn report_from_parts(
    layout: &Layout,
    omega: &[f64],
    labels: &[String],
    n_rigid: usize,
    phi1_at: impl Fn(usize, usize, usize) -> Vec<f64>,
) -> ModeReport {
    let comps = layout.components;
    let shapes = (0..omega.len())
        .map(|j| {
            let beams = layout
                .beams
                .iter()
                .enumerate()
                .map(|(b, beam)| {
                    let mut s = vec![0.0];
                    for h in &beam.element_lengths {
                        s.push(s.last().copied().unwrap_or(0.0) + h);
                    }
                    let phi1: Vec<Vec<f64>> =
                        (0..beam.n_nodes()).map(|n| phi1_at(j, b, n)).collect();
                    let velocity_global = (0..beam.n_nodes())
                        .map(|n| {
                            let e = comps.embed(&phi1[n]);
                            let v = rotation(&beam.xi(n)) * Vector3::new(e[0], e[1], e[2]);
                            [v.x, v.y, v.z]
                        })
                        .collect();
                    BeamShape {
                        name: beam.name.clone(),
                        s,
                        reference: beam.reference_positions.clone(),
                        phi1,
                        velocity_global,
                    }
                })
                .collect();
            ModeShape { index: j, frequency_rad_s: omega[j], label: labels[j].clone(), beams }
        })
        .collect();
    ModeReport { frequencies_rad_s: omega.to_vec(), labels: labels.to_vec(), n_rigid, shapes }
}
