//! Canonical reduced models: the paper's 2D and 3D two-links (§5.2–5.3, theory.md §9) with
//! the paper's mode sets and inputs. Shared by tests, benches and verification cases.

use crate::basis::{BasisSettings, KindCounts, ModalBasis, ModeSelection};
use crate::error::Result;
use crate::rom::{Input, ModalRom, RomOptions};
use crate::structure::StructureModel;
use intrinsic_beam::Section;
use multibody_constraints::samples;
use multibody_constraints::Structure;

/// A structure with its modes and reduced model.
#[derive(Clone, Debug)]
pub struct Sample {
    /// The FE structure.
    pub structure: Structure,
    /// Operators, damping and rigid candidates.
    pub model: StructureModel,
    /// All constrained modes.
    pub basis: ModalBasis,
    /// The reduced model on the selected modes.
    pub rom: ModalRom,
}

/// The paper's 2D inputs (§5.2): root torque, axial and transverse follower forces at the tip.
pub fn inputs_2d(structure: &Structure, model: &StructureModel) -> Result<Vec<Input>> {
    let tip = model.layout.beams[1].n_nodes() - 1;
    Ok(vec![
        model.joint_torque(structure, "root torque", "root", None)?,
        Input::point(&model.layout, "tip force e1", 1, tip, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0])?,
        Input::point(&model.layout, "tip force e3", 1, tip, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0])?,
    ])
}

/// The paper's 3D inputs (§5.3): two follower bending moments at the root, three follower
/// forces at the tip.
pub fn inputs_3d(structure: &Structure, model: &StructureModel) -> Result<Vec<Input>> {
    let tip = model.layout.beams[1].n_nodes() - 1;
    let mut out = vec![
        Input::point(&model.layout, "root moment e2", 0, 0, [0.0, 0.0, 0.0, 0.0, 1.0, 0.0])?,
        Input::point(&model.layout, "root moment e3", 0, 0, [0.0, 0.0, 0.0, 0.0, 0.0, 1.0])?,
    ];
    for (d, name) in ["tip force e1", "tip force e2", "tip force e3"].iter().enumerate() {
        let mut f = [0.0; 6];
        f[d] = 1.0;
        out.push(Input::point(&model.layout, name, 1, tip, f)?);
    }
    let _ = structure;
    Ok(out)
}

/// The paper's 2D two-link at `angle` (rad) with `n` elements per link, its modes and the
/// reduced model on `selection` (paper: [`KindCounts::paper_2d`]). `damped` keeps the
/// paper's `D2`.
pub fn paper_2d(
    n: usize,
    angle: f64,
    damped: bool,
    selection: &ModeSelection,
    options: &RomOptions,
) -> Result<Sample> {
    let section = if damped { Section::paper_2d() } else { Section::paper_2d().undamped() };
    let structure = samples::paper_2d(section, n, angle)?;
    build(structure, selection, options, inputs_2d)
}

/// The paper's 3D two-link (universal joints), as [`paper_2d`] (paper set: [`KindCounts::paper_3d`]).
pub fn paper_3d(
    n: usize,
    angle: f64,
    damped: bool,
    selection: &ModeSelection,
    options: &RomOptions,
) -> Result<Sample> {
    let section = if damped { Section::paper_3d() } else { Section::paper_3d().undamped() };
    let structure = samples::paper_3d(section, n, angle)?;
    build(structure, selection, options, inputs_3d)
}

/// The paper's mode set for the 2D scene.
pub fn paper_2d_selection() -> ModeSelection {
    ModeSelection::ByKind(KindCounts::paper_2d())
}

/// The paper's mode set for the 3D scene.
pub fn paper_3d_selection() -> ModeSelection {
    ModeSelection::ByKind(KindCounts::paper_3d())
}

fn build(
    structure: Structure,
    selection: &ModeSelection,
    options: &RomOptions,
    inputs: fn(&Structure, &StructureModel) -> Result<Vec<Input>>,
) -> Result<Sample> {
    let model = StructureModel::new(&structure)?;
    let basis = model.modes(&BasisSettings::default())?;
    let picked = basis.select(selection)?;
    let inputs = inputs(&structure, &model)?;
    let rom = ModalRom::new(&picked, Some(&model.damping), &inputs, options)?;
    Ok(Sample { structure, model, basis, rom })
}
