//! One-dimensional meshes along the beam: node coordinates `s_n`, element lengths `h_e`,
//! node weights `w_n = (h_{n−1} + h_n)/2` (end nodes `h/2`), theory.md §2.

use crate::error::{check_finite, BeamError, Result};

/// A (possibly non-uniform) mesh of `N ≥ 1` elements and `N + 1` nodes on `[s_0, s_N]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    nodes: Vec<f64>,
    lengths: Vec<f64>,
    weights: Vec<f64>,
}

impl Mesh {
    /// A uniform mesh of `n_elements` elements on `[0, length]`.
    ///
    /// ```
    /// use intrinsic_beam::Mesh;
    ///
    /// let mesh = Mesh::uniform(2.0, 4)?;
    /// assert_eq!(mesh.n_elements(), 4);
    /// assert!(Mesh::uniform(1.0, 0).is_err());
    /// # Ok::<(), intrinsic_beam::BeamError>(())
    /// ```
    pub fn uniform(length: f64, n_elements: usize) -> Result<Self> {
        if !crate::error::positive_finite(length) {
            return Err(BeamError::NonPositiveLength {
                field: "beam length".into(),
                value: length,
            });
        }
        if n_elements == 0 {
            return Err(BeamError::NoElements { n_elements });
        }
        let h = length / n_elements as f64;
        let nodes: Vec<f64> =
            (0..=n_elements).map(|i| if i == n_elements { length } else { i as f64 * h }).collect();
        Self::from_nodes(nodes)
    }

    /// A mesh from strictly increasing node coordinates (at least two).
    pub fn from_nodes(nodes: Vec<f64>) -> Result<Self> {
        if nodes.len() < 2 {
            return Err(BeamError::NoElements { n_elements: nodes.len().saturating_sub(1) });
        }
        for (i, &s) in nodes.iter().enumerate() {
            check_finite("mesh node coordinate", format!("{i}"), s)?;
        }
        for i in 1..nodes.len() {
            if nodes[i] <= nodes[i - 1] {
                return Err(BeamError::NonIncreasingNodes {
                    index: i,
                    value: nodes[i],
                    previous: nodes[i - 1],
                });
            }
        }
        let lengths: Vec<f64> = nodes.windows(2).map(|w| w[1] - w[0]).collect();
        let n = lengths.len();
        let weights = (0..=n)
            .map(|i| {
                let left = if i > 0 { lengths[i - 1] } else { 0.0 };
                let right = if i < n { lengths[i] } else { 0.0 };
                0.5 * (left + right)
            })
            .collect();
        Ok(Self { nodes, lengths, weights })
    }

    /// A mesh on `[0, length]` with element lengths in geometric progression (ratio
    /// `last/first = grading`), for non-uniform tests.
    pub fn graded(length: f64, n_elements: usize, grading: f64) -> Result<Self> {
        if !crate::error::positive_finite(grading) {
            return Err(BeamError::InvalidSetting {
                field: "grading".into(),
                value: grading,
                reason: "must be positive and finite".into(),
            });
        }
        if n_elements == 0 {
            return Err(BeamError::NoElements { n_elements });
        }
        if !crate::error::positive_finite(length) {
            return Err(BeamError::NonPositiveLength {
                field: "beam length".into(),
                value: length,
            });
        }
        let q = if n_elements > 1 { grading.powf(1.0 / (n_elements - 1) as f64) } else { 1.0 };
        let raw: Vec<f64> = (0..n_elements).map(|e| q.powi(e as i32)).collect();
        let total: f64 = raw.iter().sum();
        let mut nodes = vec![0.0];
        let mut s = 0.0;
        for (e, r) in raw.iter().enumerate() {
            s += r * length / total;
            nodes.push(if e + 1 == n_elements { length } else { s });
        }
        Self::from_nodes(nodes)
    }

    /// Number of elements `N`.
    pub fn n_elements(&self) -> usize {
        self.lengths.len()
    }

    /// Number of nodes `N + 1`.
    pub fn n_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Node coordinates `s_n`.
    pub fn nodes(&self) -> &[f64] {
        &self.nodes
    }

    /// Element lengths `h_e`.
    pub fn lengths(&self) -> &[f64] {
        &self.lengths
    }

    /// Node weights `w_n` (lumped lengths).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Total length `L = s_N − s_0`.
    pub fn length(&self) -> f64 {
        self.nodes[self.nodes.len() - 1] - self.nodes[0]
    }

    /// Largest element length.
    pub fn max_length(&self) -> f64 {
        self.lengths.iter().cloned().fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_length() {
        let m = Mesh::graded(2.0, 7, 3.0).unwrap();
        let sum_w: f64 = m.weights().iter().sum();
        let sum_h: f64 = m.lengths().iter().sum();
        assert!((sum_w - 2.0).abs() < 1e-14 && (sum_h - 2.0).abs() < 1e-14);
        assert!((m.lengths()[6] / m.lengths()[0] - 3.0).abs() < 1e-12);
        let u = Mesh::uniform(1.0, 4).unwrap();
        assert_eq!(u.weights(), &[0.125, 0.25, 0.25, 0.25, 0.125]);
    }

    #[test]
    fn bad_meshes_are_errors() {
        assert!(matches!(Mesh::uniform(0.0, 3), Err(BeamError::NonPositiveLength { .. })));
        assert!(matches!(Mesh::uniform(-1.0, 3), Err(BeamError::NonPositiveLength { .. })));
        assert!(matches!(Mesh::uniform(f64::NAN, 3), Err(BeamError::NonPositiveLength { .. })));
        assert!(matches!(Mesh::uniform(1.0, 0), Err(BeamError::NoElements { .. })));
        assert!(matches!(
            Mesh::from_nodes(vec![0.0, 0.5, 0.5]),
            Err(BeamError::NonIncreasingNodes { index: 2, .. })
        ));
        assert!(Mesh::from_nodes(vec![0.0]).is_err());
    }
}
