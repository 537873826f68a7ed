//! The names a scene file may give (joint kinds, frames, presets): serde enums, so that an unknown name is refused at parse time with the list of
//! the accepted ones, and each maps to its library type.

use serde::Deserialize;

/// A named mode set of the controller model (`[modes] selection`).
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
pub enum ModeSet {
    /// 2 rigid + 4 axial + 4 bending modes (paper §5.2).
    #[serde(rename = "paper-2d")]
    Paper2d,
    /// 4 rigid + 4 axial + 4 torsion + 4 + 4 bending modes (paper §5.3).
    #[serde(rename = "paper-3d")]
    Paper3d,
}

impl ModeSet {
    /// The library's mode selection of this set.
    pub fn selection(self) -> modal_rom::ModeSelection {
        match self {
            ModeSet::Paper2d => modal_rom::samples::paper_2d_selection(),
            ModeSet::Paper3d => modal_rom::samples::paper_3d_selection(),
        }
    }
}

/// `components`: the motion a structure has.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ComponentsName {
    /// Motion in the e1–e3 plane, rotation about e2.
    Planar,
    /// Full 3D motion.
    Spatial,
}

impl From<ComponentsName> for intrinsic_beam::Components {
    fn from(c: ComponentsName) -> Self {
        match c {
            ComponentsName::Planar => intrinsic_beam::Components::Planar,
            ComponentsName::Spatial => intrinsic_beam::Components::Spatial,
        }
    }
}

/// A section preset of the paper (theory.md §9).
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
pub enum SectionPreset {
    /// The 2D two-link's section (§5.2).
    #[serde(rename = "paper-2d")]
    Paper2d,
    /// The 3D two-link's section (§5.3).
    #[serde(rename = "paper-3d")]
    Paper3d,
}

/// The kind of a joint or support (its parameters are fields of [`super::JointSpec`]).
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum JointKindName {
    /// All six relative motions locked (also `rigid`).
    #[serde(alias = "rigid")]
    Weld,
    /// Rotations free.
    Ball,
    /// One rotation free, about `axis`.
    Hinge,
    /// Two rotations free (also `wheel`).
    #[serde(alias = "wheel")]
    Universal,
    /// Each translation and rotation `rigid` or `free`.
    Custom,
}

/// A custom joint's axis: locked or free.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum FreedomName {
    /// Locked.
    Rigid,
    /// Free.
    Free,
}

/// The frame of a point load.
#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LoadFrameName {
    /// The node's local frame (turns with the beam).
    Follower,
    /// The global frame.
    Dead,
}
