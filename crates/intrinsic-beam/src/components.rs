//! Component sets: planar (`k = 3`: `v1, v3, ω2 | f1, f3, m2`) or spatial (`k = 6`).
//!
//! A planar beam lies in the local e1–e3 plane and bends about e2; it carries only the three
//! in-plane components of each field and must reproduce the spatial answer for planar data
//! (theory.md §1). [`Components::indices`] maps the `k` active components to their positions
//! in the 6-vectors `[1,2,3 | 1,2,3]`.

use nalgebra::{Matrix6, Vector6};
use serde::{Deserialize, Serialize};

use crate::error::{BeamError, Result};
use crate::section::Section;

/// Which components of `x1`, `x2` a beam carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Components {
    /// `k = 3`: `[v1, v3, ω2]` and `[f1, f3, m2]` (6-vector positions 0, 2, 4).
    Planar,
    /// `k = 6`: all components.
    Spatial,
}

/// 6-vector positions of the planar components.
pub const PLANAR_INDICES: [usize; 3] = [0, 2, 4];
/// 6-vector positions of the spatial components.
pub const SPATIAL_INDICES: [usize; 6] = [0, 1, 2, 3, 4, 5];
/// 6-vector positions that a planar beam leaves out (`v2, ω1, ω3 | f2, m1, m3`).
pub const OUT_OF_PLANE_INDICES: [usize; 3] = [1, 3, 5];

impl Components {
    /// Number of components per field, `k`.
    pub fn k(self) -> usize {
        match self {
            Self::Planar => 3,
            Self::Spatial => 6,
        }
    }

    /// Positions of the active components in a 6-vector.
    pub fn indices(self) -> &'static [usize] {
        match self {
            Self::Planar => &PLANAR_INDICES,
            Self::Spatial => &SPATIAL_INDICES,
        }
    }

    /// Index in the spatial 6-vector of active component `c` (`0 ≤ c < k`).
    #[inline]
    pub fn spatial_index(self, c: usize) -> usize {
        self.indices()[c]
    }

    /// Active component holding spatial index `s` (`0..6`), if any.
    pub fn active_index(self, s: usize) -> Option<usize> {
        self.indices().iter().position(|&i| i == s)
    }

    /// Embeds `k` components into a 6-vector (zeros elsewhere).
    #[inline]
    pub fn embed(self, x: &[f64]) -> Vector6<f64> {
        let mut out = Vector6::zeros();
        for (a, &i) in self.indices().iter().enumerate() {
            out[i] = x[a];
        }
        out
    }

    /// Extracts the `k` active components of a 6-vector into `out`.
    #[inline]
    pub fn extract(self, x: &Vector6<f64>, out: &mut [f64]) {
        for (a, &i) in self.indices().iter().enumerate() {
            out[a] = x[i];
        }
    }

    /// The active components of a 6-vector as a `Vec` of length `k`.
    pub fn reduce(self, x: &Vector6<f64>) -> Vec<f64> {
        self.indices().iter().map(|&i| x[i]).collect()
    }

    /// Entry `(a, b)` of the `k×k` restriction of a 6×6 matrix.
    #[inline]
    pub fn entry(self, m: &Matrix6<f64>, a: usize, b: usize) -> f64 {
        let idx = self.indices();
        m[(idx[a], idx[b])]
    }

    /// Checks that a section is usable with this component set: for `Planar`, no coupling
    /// between in-plane and out-of-plane components in `M`, `C`, `D0..2`, and `κ0 = κ0₂ e2`.
    pub fn check_section(self, section: &Section) -> Result<()> {
        if self == Self::Spatial {
            return Ok(());
        }
        for (name, m) in [
            ("section.mass", &section.mass),
            ("section.compliance", &section.compliance),
            ("section.d0", &section.d0),
            ("section.d1", &section.d1),
            ("section.d2", &section.d2),
        ] {
            for &i in &PLANAR_INDICES {
                for &j in &OUT_OF_PLANE_INDICES {
                    for (r, c) in [(i, j), (j, i)] {
                        if m[(r, c)] != 0.0 {
                            return Err(BeamError::NotPlanar {
                                what: name.into(),
                                index: format!("({r},{c})"),
                                value: m[(r, c)],
                            });
                        }
                    }
                }
            }
        }
        for i in [0, 2] {
            if section.kappa0[i] != 0.0 {
                return Err(BeamError::NotPlanar {
                    what: "section.kappa0".into(),
                    index: format!("{i}"),
                    value: section.kappa0[i],
                });
            }
        }
        Ok(())
    }

    /// Checks that a 6-vector (a load, an end value) has no out-of-plane entry when planar.
    pub fn check_vector(self, what: &str, x: &Vector6<f64>) -> Result<()> {
        if self == Self::Planar {
            for &j in &OUT_OF_PLANE_INDICES {
                if x[j] != 0.0 {
                    return Err(BeamError::NotPlanar {
                        what: what.into(),
                        index: format!("{j}"),
                        value: x[j],
                    });
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embed_extract_round_trip() {
        let c = Components::Planar;
        let x6 = c.embed(&[1.0, 2.0, 3.0]);
        assert_eq!(x6, Vector6::new(1.0, 0.0, 2.0, 0.0, 3.0, 0.0));
        let mut back = [0.0; 3];
        c.extract(&x6, &mut back);
        assert_eq!(back, [1.0, 2.0, 3.0]);
        assert_eq!(Components::Spatial.reduce(&x6).len(), 6);
    }

    #[test]
    fn planar_rejects_coupled_section() {
        let mut s = Section::paper_3d();
        assert!(Components::Planar.check_section(&s).is_ok());
        s.compliance[(0, 1)] = 1e-4;
        s.compliance[(1, 0)] = 1e-4;
        assert!(Components::Planar.check_section(&s).is_err());
        assert!(Components::Spatial.check_section(&s).is_ok());
        let load = Vector6::new(0.0, 1.0, 0.0, 0.0, 0.0, 0.0);
        assert!(Components::Planar.check_vector("load", &load).is_err());
    }
}
