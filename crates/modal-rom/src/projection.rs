//! FE state ↔ modal coordinates (theory.md §7), and reconstruction of fields, rotations and
//! positions for plots.
//!
//! `q1 = (Φ1ᵀB1Φ1)⁻¹ Φ1ᵀ B1 x1`, `q2 = (Φ2ᵀB2Φ2)⁻¹ Φ2ᵀ B2 x2`, `qξ = Aξ⁻¹ ⟨Φξ, ξ⟩`: the
//! energy-norm projections. With orthonormal modes they are theory.md's `⟨φ1i, M x1⟩`,
//! `⟨φ2i, C x2⟩`; the Gram factors absorb the `~1e-9` C-orthonormality defect of `φ2`
//! (theory.md §4), so project → reconstruct → project is exact to round-off.

use crate::error::{shape, Result};
use crate::layout::FullIndex;
use crate::rom::ModalRom;
use intrinsic_beam::rotation::rotation;
use nalgebra::{Vector3, Vector4};

/// Fields rebuilt from modal coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Fields {
    /// Node velocities `X1` (n1).
    pub x1: Vec<f64>,
    /// Element forces `X2` (n2).
    pub x2: Vec<f64>,
    /// Quaternion per node of all beams (normalised for use as rotations), when carried.
    pub xi: Option<Vec<[f64; 4]>>,
}

impl ModalRom {
    /// Modal coordinates of FE fields `x1` (n1), `x2` (n2) and, for the augmented model,
    /// node quaternions `xi` (all beams' nodes in order; ignored without quaternion states,
    /// and the reference field is used when `None`).
    pub fn project(&self, x1: &[f64], x2: &[f64], xi: Option<&[[f64; 4]]>) -> Result<Vec<f64>> {
        let (n1, n2) = (self.layout.n1(), self.layout.n2());
        if x1.len() != n1 {
            return Err(shape("x1", (n1, 1), (x1.len(), 1)));
        }
        if x2.len() != n2 {
            return Err(shape("x2", (n2, 1), (x2.len(), 1)));
        }
        let mut q = vec![0.0; self.n_state()];
        let m = self.n_modes();
        for i in 0..m {
            q[i] = (0..n1).map(|r| self.proj1[(i, r)] * x1[r]).sum();
        }
        let o2 = self.q2_offset();
        for p in 0..self.n_q2() {
            q[o2 + p] = (0..n2).map(|r| self.proj2[(p, r)] * x2[r]).sum();
        }
        if let Some(qm) = &self.quaternion {
            let nodes = qm.weights.len();
            let field: Vec<Vector4<f64>> = match xi {
                Some(v) => {
                    if v.len() != nodes {
                        return Err(shape("xi (one per node)", (nodes, 4), (v.len(), 4)));
                    }
                    v.iter().map(|a| Vector4::from_column_slice(a)).collect()
                }
                None => self
                    .layout
                    .beams
                    .iter()
                    .flat_map(|b| (0..b.n_nodes()).map(move |n| b.xi(n)))
                    .collect(),
            };
            let nx = qm.kept.len();
            let rhs: Vec<f64> = (0..nx)
                .map(|c| {
                    (0..nodes)
                        .map(|n| {
                            qm.weights[n]
                                * (0..4)
                                    .map(|a| qm.phi_xi[(4 * n + a, c)] * field[n][a])
                                    .sum::<f64>()
                        })
                        .sum()
                })
                .collect();
            let ox = self.xi_offset();
            for i in 0..nx {
                q[ox + i] = (0..nx).map(|p| qm.a_xi_inv[(i, p)] * rhs[p]).sum();
            }
        }
        Ok(q)
    }

    /// Modal coordinates of a full FE vector (ordering of theory.md §2; end values ignored).
    pub fn project_full(&self, x: &[f64], xi: Option<&[[f64; 4]]>) -> Result<Vec<f64>> {
        let nf = self.layout.n_full();
        if x.len() != nf {
            return Err(shape("FE state", (nf, 1), (x.len(), 1)));
        }
        let mut x1 = vec![0.0; self.layout.n1()];
        let mut x2 = vec![0.0; self.layout.n2()];
        for (i, &v) in x.iter().enumerate() {
            match self.layout.classify_full(i) {
                FullIndex::X1(p) => x1[p] = v,
                FullIndex::X2(p) => x2[p] = v,
                _ => {}
            }
        }
        self.project(&x1, &x2, xi)
    }

    /// Fields `x1 = Φ1 q1`, `x2 = Φ2 q2`, `ξ = Φξ qξ` (normalised per node).
    pub fn reconstruct(&self, q: &[f64]) -> Result<Fields> {
        if q.len() != self.n_state() {
            return Err(shape("state q", (self.n_state(), 1), (q.len(), 1)));
        }
        let (n1, n2) = (self.layout.n1(), self.layout.n2());
        let m = self.n_modes();
        let x1 = (0..n1).map(|r| (0..m).map(|j| self.phi1[(r, j)] * q[j]).sum()).collect();
        let o2 = self.q2_offset();
        let x2 = (0..n2)
            .map(|r| {
                self.q2_modes.iter().enumerate().map(|(p, &j)| self.phi2[(r, j)] * q[o2 + p]).sum()
            })
            .collect();
        let xi = self.quaternion.as_ref().map(|qm| {
            let ox = self.xi_offset();
            (0..qm.weights.len())
                .map(|n| {
                    let v: Vector4<f64> = Vector4::from_fn(|a, _| {
                        (0..qm.kept.len()).map(|c| qm.phi_xi[(4 * n + a, c)] * q[ox + c]).sum()
                    });
                    let v = v / v.norm();
                    [v[0], v[1], v[2], v[3]]
                })
                .collect()
        });
        Ok(Fields { x1, x2, xi })
    }

    /// The full FE vector (ordering of theory.md §2, end values zero) of modal coordinates.
    pub fn reconstruct_full(&self, q: &[f64]) -> Result<Vec<f64>> {
        let f = self.reconstruct(q)?;
        let mut x = vec![0.0; self.layout.n_full()];
        for (i, v) in x.iter_mut().enumerate() {
            match self.layout.classify_full(i) {
                FullIndex::X1(p) => *v = f.x1[p],
                FullIndex::X2(p) => *v = f.x2[p],
                _ => {}
            }
        }
        Ok(x)
    }

    /// Node positions of every beam rebuilt in space (eq. 10): `r_{n+1} = r_n + h T(ξ_mid)(e1 + γ_e)`
    /// with `γ` from `C x2` and `ξ` the modal quaternion field (or, without quaternion states,
    /// the reference orientations). Each beam starts at its `start_from` node or at `r̄_0`.
    pub fn positions(&self, q: &[f64]) -> Result<Vec<Vec<[f64; 3]>>> {
        let f = self.reconstruct(q)?;
        let comps = self.layout.components;
        let k = comps.k();
        let mut out: Vec<Vec<[f64; 3]>> = Vec::new();
        let mut node0 = 0;
        for (b, beam) in self.layout.beams.iter().enumerate() {
            let xi = |n: usize| -> Vector4<f64> {
                match &f.xi {
                    Some(v) => Vector4::from_column_slice(&v[node0 + n]),
                    None => beam.xi(n),
                }
            };
            let start = match beam.start_from {
                Some((p, n)) => Vector3::from_column_slice(&out[p][n]),
                None => beam.position(0),
            };
            let mut r = vec![[start.x, start.y, start.z]];
            let c = &self.compliance[b];
            for e in 0..beam.n_elements() {
                let i0 = self.layout.x2_index(b, e, 0);
                let mut strain = vec![0.0; k];
                for a in 0..k {
                    strain[a] = (0..k).map(|bb| c[a * k + bb] * f.x2[i0 + bb]).sum();
                }
                let s6 = comps.embed(&strain);
                let gamma = Vector3::new(s6[0], s6[1], s6[2]);
                let (xa, mut xb) = (xi(e), xi(e + 1));
                if xa.dot(&xb) < 0.0 {
                    xb = -xb;
                }
                let mid = (xa + xb).normalize();
                let prev = Vector3::from_column_slice(&r[e]);
                let next = prev + rotation(&mid) * (Vector3::x() + gamma) * beam.element_lengths[e];
                r.push([next.x, next.y, next.z]);
            }
            out.push(r);
            node0 += beam.n_nodes();
        }
        Ok(out)
    }
}
