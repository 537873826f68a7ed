//! Where each beam's nodal and element values sit in the stacked modal vectors (theory.md §2).
//!
//! The FE unknown vector of a structure (theory.md §2) is, per beam with `N` elements,
//! `[x1_0 … x1_N, x2_0 … x2_{N−1}, x2_L, x2_R]` (length `k(2N+3)`), beams concatenated.
//! The eigen route of theory.md §4 splits it into `X1` (all node velocities, beams
//! concatenated) and `X2` (all element forces); the end values `x2_L/R` are reactions and do
//! not appear in the modes. [`Layout`] maps between the three numberings.

use crate::error::{invalid, Result};
use nalgebra::{Vector3, Vector4};
use serde::{Deserialize, Serialize};

/// Active components per field (planar `k = 3` or spatial `k = 6`): the beam layer's type.
pub use intrinsic_beam::Components;

/// One beam's discretisation and reference configuration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BeamLayout {
    /// Beam name (for messages and exports).
    pub name: String,
    /// Element lengths `h_e`, `e = 0…N−1` (all > 0).
    pub element_lengths: Vec<f64>,
    /// Reference quaternion `ξ̄_n` (local → global, scalar first) at each node `n = 0…N`.
    pub reference_quaternions: Vec<[f64; 4]>,
    /// Reference position `r̄_n` (global) of each node `n = 0…N`.
    pub reference_positions: Vec<[f64; 3]>,
    /// `(beam, node)` of an earlier beam whose node this beam's `s = 0` end is joined to, for
    /// rebuilding positions from strains; `None`: the beam starts at its reference `r̄_0`.
    pub start_from: Option<(usize, usize)>,
}

impl BeamLayout {
    /// Number of elements `N`.
    pub fn n_elements(&self) -> usize {
        self.element_lengths.len()
    }

    /// Number of nodes `N + 1`.
    pub fn n_nodes(&self) -> usize {
        self.element_lengths.len() + 1
    }

    /// Lumped node weight `w_n = (h_{n−1} + h_n)/2` (end nodes `h/2`), theory.md §2.
    pub fn node_weight(&self, n: usize) -> f64 {
        let h = &self.element_lengths;
        let left = if n > 0 { h[n - 1] } else { 0.0 };
        let right = if n < h.len() { h[n] } else { 0.0 };
        0.5 * (left + right)
    }

    /// Reference quaternion of node `n` as a vector.
    pub fn xi(&self, n: usize) -> Vector4<f64> {
        Vector4::from_column_slice(&self.reference_quaternions[n])
    }

    /// Reference position of node `n` as a vector.
    pub fn position(&self, n: usize) -> Vector3<f64> {
        Vector3::from_column_slice(&self.reference_positions[n])
    }

    /// A straight uniform beam of length `length` with `n_elements` elements, starting at
    /// `origin`, its local frame given by the unit quaternion `xi` (e1 along the beam).
    pub fn straight(
        name: &str,
        length: f64,
        n_elements: usize,
        origin: [f64; 3],
        xi: [f64; 4],
    ) -> Self {
        let h = length / n_elements as f64;
        let t = intrinsic_beam::rotation::rotation(&Vector4::from_column_slice(&xi));
        let e1 = t * Vector3::x();
        let reference_positions = (0..=n_elements)
            .map(|n| {
                let p = Vector3::from_column_slice(&origin) + e1 * (h * n as f64);
                [p.x, p.y, p.z]
            })
            .collect();
        BeamLayout {
            name: name.to_string(),
            element_lengths: vec![h; n_elements],
            reference_quaternions: vec![xi; n_elements + 1],
            reference_positions,
            start_from: None,
        }
    }
}

/// The layout of a whole structure: components and beams in order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layout {
    /// Planar or spatial components.
    pub components: Components,
    /// Beams in structure order.
    pub beams: Vec<BeamLayout>,
}

impl Layout {
    /// Builds and validates a layout.
    pub fn new(components: Components, beams: Vec<BeamLayout>) -> Result<Self> {
        let layout = Layout { components, beams };
        layout.validate()?;
        Ok(layout)
    }

    /// Checks element lengths, array lengths, unit quaternions and `start_from` references.
    pub fn validate(&self) -> Result<()> {
        if self.beams.is_empty() {
            return Err(invalid("layout.beams", 0, "a structure needs at least one beam"));
        }
        for (b, beam) in self.beams.iter().enumerate() {
            if beam.element_lengths.is_empty() {
                return Err(invalid(
                    format!("beams[{b}].element_lengths"),
                    "[]",
                    "at least one element",
                ));
            }
            if let Some((e, h)) =
                beam.element_lengths.iter().enumerate().find(|(_, h)| !(h.is_finite() && **h > 0.0))
            {
                return Err(invalid(
                    format!("beams[{b}].element_lengths[{e}]"),
                    h,
                    "must be finite and > 0",
                ));
            }
            let nodes = beam.n_nodes();
            if beam.reference_quaternions.len() != nodes {
                return Err(invalid(
                    format!("beams[{b}].reference_quaternions"),
                    beam.reference_quaternions.len(),
                    format!("need one per node ({nodes})"),
                ));
            }
            if beam.reference_positions.len() != nodes {
                return Err(invalid(
                    format!("beams[{b}].reference_positions"),
                    beam.reference_positions.len(),
                    format!("need one per node ({nodes})"),
                ));
            }
            for (n, q) in beam.reference_quaternions.iter().enumerate() {
                let norm = Vector4::from_column_slice(q).norm();
                if !norm.is_finite() || (norm - 1.0).abs() > 1e-9 {
                    return Err(invalid(
                        format!("beams[{b}].reference_quaternions[{n}]"),
                        norm,
                        "must be a unit quaternion",
                    ));
                }
            }
            if let Some((p, n)) = beam.start_from {
                if p >= b || n >= self.beams[p].n_nodes() {
                    return Err(invalid(
                        format!("beams[{b}].start_from"),
                        format!("({p}, {n})"),
                        "must name a node of an earlier beam",
                    ));
                }
            }
        }
        Ok(())
    }

    /// Components per field, `k`.
    pub fn k(&self) -> usize {
        self.components.k()
    }

    /// Length of `X1` (all node values): `k Σ (N_b + 1)`.
    pub fn n1(&self) -> usize {
        self.k() * self.beams.iter().map(|b| b.n_nodes()).sum::<usize>()
    }

    /// Length of `X2` (all element values): `k Σ N_b`.
    pub fn n2(&self) -> usize {
        self.k() * self.beams.iter().map(|b| b.n_elements()).sum::<usize>()
    }

    /// Length of the full FE vector (theory.md §2): `k Σ (2 N_b + 3)`.
    pub fn n_full(&self) -> usize {
        self.k() * self.beams.iter().map(|b| 2 * b.n_elements() + 3).sum::<usize>()
    }

    /// Offset of beam `b`'s first node in `X1`.
    pub fn x1_offset(&self, b: usize) -> usize {
        self.k() * self.beams[..b].iter().map(|x| x.n_nodes()).sum::<usize>()
    }

    /// Offset of beam `b`'s first element in `X2`.
    pub fn x2_offset(&self, b: usize) -> usize {
        self.k() * self.beams[..b].iter().map(|x| x.n_elements()).sum::<usize>()
    }

    /// Offset of beam `b` in the full FE vector.
    pub fn full_offset(&self, b: usize) -> usize {
        self.k() * self.beams[..b].iter().map(|x| 2 * x.n_elements() + 3).sum::<usize>()
    }

    /// Index in `X1` of component `c` at node `n` of beam `b`.
    pub fn x1_index(&self, b: usize, n: usize, c: usize) -> usize {
        self.x1_offset(b) + n * self.k() + c
    }

    /// Index in `X2` of component `c` at element `e` of beam `b`.
    pub fn x2_index(&self, b: usize, e: usize, c: usize) -> usize {
        self.x2_offset(b) + e * self.k() + c
    }

    /// Classifies an index of the full FE vector.
    pub fn classify_full(&self, index: usize) -> FullIndex {
        let k = self.k();
        let mut offset = 0;
        for (b, beam) in self.beams.iter().enumerate() {
            let len = k * (2 * beam.n_elements() + 3);
            if index < offset + len {
                let local = index - offset;
                let nodes = k * beam.n_nodes();
                let elems = k * beam.n_elements();
                return if local < nodes {
                    FullIndex::X1(self.x1_offset(b) + local)
                } else if local < nodes + elems {
                    FullIndex::X2(self.x2_offset(b) + local - nodes)
                } else {
                    FullIndex::End
                };
            }
            offset += len;
        }
        FullIndex::OutOfRange
    }

    /// Total number of nodes over all beams.
    pub fn n_nodes_total(&self) -> usize {
        self.beams.iter().map(|b| b.n_nodes()).sum()
    }
}

/// What an index of the full FE vector refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FullIndex {
    /// A node value; the index in `X1`.
    X1(usize),
    /// An element value; the index in `X2`.
    X2(usize),
    /// A beam end value `x2_L` or `x2_R` (reaction).
    End,
    /// Past the end of the vector.
    OutOfRange,
}
