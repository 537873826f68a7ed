//! The optimal control problem (33)–(34) in multiple-shooting form.

use crate::error::{check_dim, invalid, Result};
use nalgebra::{DMatrix, DVector};

/// An optimal control problem (paper eqs. 33–34) on a fixed horizon:
///
/// `min ∫₀^τp V(x, u) dt`, `V = ½(x − x_r)ᵀQ(x − x_r) + ½(u − u_r)ᵀR(u − u_r)`,
/// subject to `ẋ = f(x, u)`, `x(0) = x₀`, `u_min ≤ u ≤ u_max`, `x_min ≤ x ≤ x_max`,
/// with `u` piecewise constant on `Nc` equal intervals of length `Δt = τp/Nc`.
///
/// **Cost discretisation.** The control part is integrated exactly (piecewise constant);
/// the state part by the trapezoidal rule on the shooting nodes `s_k = x(kΔt)`:
/// `J = Σ_{k=0}^{Nc−1} Δt ½(u_k − u_r)ᵀR(u_k − u_r) + Σ_{k=0}^{Nc} c_k Δt ½(s_k − x_r,k)ᵀQ(s_k − x_r,k)
///      + ½(s_Nc − x_r,Nc)ᵀ P (s_Nc − x_r,Nc)`, `c_0 = c_Nc = ½`, `c_k = 1` otherwise
/// (second order in `Δt`; `P` an optional extra terminal weight, zero by default).
///
/// **Reference profile.** `x_r,k = x_r` at every node unless per-node references
/// ([`Ocp::x_ref_nodes`]) are given: then `x_r,k` is the reference at the node's time `kΔt`
/// (a reference that moves over the horizon). The cost stays quadratic in the nodes, so
/// nothing else changes; with no per-node references the problem is the constant-reference
/// one, operation for operation.
/// The cost is then exactly quadratic in the shooting variables, so the Gauss–Newton
/// Hessian is the cost Hessian and needs no integrator work.
#[derive(Clone, Debug, PartialEq)]
pub struct Ocp {
    /// Horizon `τp` (s), > 0.
    pub horizon: f64,
    /// Number of control (= shooting) intervals `Nc`, ≥ 1.
    pub intervals: usize,
    /// State weight `Q` (`nx × nx`, symmetric positive semidefinite).
    pub q: DMatrix<f64>,
    /// Control weight `R` (`nu × nu`, symmetric positive definite).
    pub r: DMatrix<f64>,
    /// Extra terminal weight `P` (`nx × nx`, symmetric PSD). Default zero.
    pub terminal: DMatrix<f64>,
    /// State reference `x_r`. Default zero.
    pub x_ref: DVector<f64>,
    /// Per-node state references `x_r,0 … x_r,Nc` (each `nx`); empty (default): `x_r` at
    /// every node.
    pub x_ref_nodes: Vec<DVector<f64>>,
    /// Control reference `u_r`. Default zero.
    pub u_ref: DVector<f64>,
    /// Lower control bounds (may be `-∞`). Default `-∞`.
    pub u_min: DVector<f64>,
    /// Upper control bounds (may be `+∞`). Default `+∞`.
    pub u_max: DVector<f64>,
    /// Lower state bounds on the nodes `s_1 … s_Nc` (may be `-∞`). Default `-∞`.
    pub x_min: DVector<f64>,
    /// Upper state bounds on the nodes `s_1 … s_Nc` (may be `+∞`). Default `+∞`.
    pub x_max: DVector<f64>,
}

impl Ocp {
    /// A problem with `Q = I`, `R = I`, zero references, no bounds.
    pub fn new(nx: usize, nu: usize, horizon: f64, intervals: usize) -> Result<Self> {
        let ocp = Self {
            horizon,
            intervals,
            q: DMatrix::identity(nx, nx),
            r: DMatrix::identity(nu, nu),
            terminal: DMatrix::zeros(nx, nx),
            x_ref: DVector::zeros(nx),
            x_ref_nodes: Vec::new(),
            u_ref: DVector::zeros(nu),
            u_min: DVector::from_element(nu, f64::NEG_INFINITY),
            u_max: DVector::from_element(nu, f64::INFINITY),
            x_min: DVector::from_element(nx, f64::NEG_INFINITY),
            x_max: DVector::from_element(nx, f64::INFINITY),
        };
        ocp.validate()?;
        Ok(ocp)
    }

    /// State dimension.
    pub fn nx(&self) -> usize {
        self.q.nrows()
    }
    /// Control dimension.
    pub fn nu(&self) -> usize {
        self.r.nrows()
    }
    /// Interval length `Δt = τp / Nc`.
    pub fn interval(&self) -> f64 {
        self.horizon / self.intervals as f64
    }

    /// Whether any state bound is finite.
    pub fn has_state_bounds(&self) -> bool {
        self.x_min.iter().chain(self.x_max.iter()).any(|v| v.is_finite())
    }

    /// Checks dimensions, finiteness, symmetry and bound ordering.
    pub fn validate(&self) -> Result<()> {
        let nx = self.q.nrows();
        let nu = self.r.nrows();
        if !(self.horizon > 0.0 && self.horizon.is_finite()) {
            return Err(invalid("horizon", self.horizon, "must be positive and finite"));
        }
        if self.intervals == 0 {
            return Err(invalid("intervals", self.intervals, "must be at least 1"));
        }
        if nx == 0 {
            return Err(invalid("q", "0×0", "nx must be at least 1"));
        }
        check_dim("q columns", nx, self.q.ncols())?;
        check_dim("r columns", nu, self.r.ncols())?;
        check_dim("terminal rows", nx, self.terminal.nrows())?;
        check_dim("terminal columns", nx, self.terminal.ncols())?;
        check_dim("x_ref", nx, self.x_ref.len())?;
        check_dim("u_ref", nu, self.u_ref.len())?;
        check_dim("u_min", nu, self.u_min.len())?;
        check_dim("u_max", nu, self.u_max.len())?;
        check_dim("x_min", nx, self.x_min.len())?;
        check_dim("x_max", nx, self.x_max.len())?;
        for (name, m) in [("q", &self.q), ("r", &self.r), ("terminal", &self.terminal)] {
            if !m.iter().all(|v| v.is_finite()) {
                return Err(invalid(name, "non-finite entry", "weights must be finite"));
            }
            let asym = (m - m.transpose()).amax();
            if asym > 1e-12 * (1.0 + m.amax()) {
                return Err(invalid(
                    name,
                    format!("asymmetry {asym:e}"),
                    "weights must be symmetric",
                ));
            }
        }
        for (name, v) in [("x_ref", &self.x_ref), ("u_ref", &self.u_ref)] {
            if !v.iter().all(|v| v.is_finite()) {
                return Err(invalid(name, "non-finite entry", "references must be finite"));
            }
        }
        if !self.x_ref_nodes.is_empty() {
            check_dim("x_ref_nodes", self.intervals + 1, self.x_ref_nodes.len())?;
            for (k, r) in self.x_ref_nodes.iter().enumerate() {
                check_dim("x_ref_nodes entry", nx, r.len())?;
                if !r.iter().all(|v| v.is_finite()) {
                    return Err(invalid(
                        "x_ref_nodes",
                        format!("non-finite entry at node {k}"),
                        "references must be finite",
                    ));
                }
            }
        }
        for i in 0..nu {
            if self.u_min[i].is_nan() || self.u_max[i].is_nan() || self.u_min[i] > self.u_max[i] {
                return Err(invalid(
                    "u_min/u_max",
                    format!("[{}, {}] at {i}", self.u_min[i], self.u_max[i]),
                    "need u_min ≤ u_max",
                ));
            }
        }
        for i in 0..nx {
            if self.x_min[i].is_nan() || self.x_max[i].is_nan() || self.x_min[i] > self.x_max[i] {
                return Err(invalid(
                    "x_min/x_max",
                    format!("[{}, {}] at {i}", self.x_min[i], self.x_max[i]),
                    "need x_min ≤ x_max",
                ));
            }
        }
        Ok(())
    }

    /// The discretised cost `J` (see the type's documentation) of the nodes `s_0 … s_Nc` and
    /// controls `u_0 … u_{Nc−1}`.
    pub fn cost(&self, s: &[DVector<f64>], u: &[DVector<f64>]) -> Result<f64> {
        check_dim("nodes", self.intervals + 1, s.len())?;
        check_dim("controls", self.intervals, u.len())?;
        let mut j = 0.0;
        for (k, sk) in s.iter().enumerate() {
            check_dim("node", self.nx(), sk.len())?;
            let e = sk - self.node_reference(k);
            j += 0.5 * self.node_weight(k) * e.dot(&(&self.q * &e));
            if k == self.intervals {
                j += 0.5 * e.dot(&(&self.terminal * &e));
            }
        }
        for uk in u {
            check_dim("control", self.nu(), uk.len())?;
            let e = uk - &self.u_ref;
            j += 0.5 * self.interval() * e.dot(&(&self.r * &e));
        }
        Ok(j)
    }

    /// The state reference `x_r,k` of node `k` (the per-node one if given, else `x_r`).
    pub fn node_reference(&self, k: usize) -> &DVector<f64> {
        self.x_ref_nodes.get(k).unwrap_or(&self.x_ref)
    }

    /// Weight `c_k Δt` of node `k` in the trapezoidal state cost.
    pub(crate) fn node_weight(&self, k: usize) -> f64 {
        let dt = self.interval();
        if k == 0 || k == self.intervals {
            0.5 * dt
        } else {
            dt
        }
    }
}
