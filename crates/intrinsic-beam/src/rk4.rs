//! Explicit classical Runge–Kutta (RK4) for single-beam problems that are ODEs (no rigid or
//! massless active direction), for cross-checks of the implicit midpoint rule.
//!
//! State: node velocities (except prescribed-velocity end components, set from their
//! amplitude), element forces, node quaternions and positions. End force components are set to
//! `∓F(t)`; the reaction of a prescribed component follows from its node equation. Rates:
//! `w_n M ẋ1_n = f_n` (eq. 1), `h_e C ẋ2_e = f_e` (eq. 2), `ξ̇ = U(ω)ξ`, `ṙ = T(ξ) v`
//! (eqs. 7, 10); quaternions are renormalised after each step.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3, Vector4};

use crate::beam::Beam;
use crate::error::{check_len, BeamError, Result};
use crate::kinematics::Kinematics;
use crate::operators::halves;
use crate::problem::{BeamProblem, End};
use crate::rotation::{rotation, u_matrix};

/// RK4 integrator of a [`BeamProblem`].
#[derive(Clone, Debug)]
pub struct ExplicitRk4 {
    problem: BeamProblem,
    state: Vec<f64>,
    kinematics: Kinematics,
    time: f64,
    m_inv: DMatrix<f64>,
    c_inv: DMatrix<f64>,
    m_red: DMatrix<f64>,
}

impl ExplicitRk4 {
    /// Starts at `time = 0`. Errors with [`BeamError::NotAnOde`] if the section has a rigid or
    /// massless active direction.
    ///
    /// ```
    /// use intrinsic_beam::samples::{cantilever_swing_with, soft_section};
    /// use intrinsic_beam::{Components, ExplicitRk4};
    ///
    /// // an ODE sample (inertia and compliance in every direction), 4 elements
    /// let s = cantilever_swing_with(soft_section(), Components::Planar, 4)?;
    /// let mut rk = ExplicitRk4::new(s.problem, s.state, s.kinematics)?;
    /// rk.step(1e-4)?;
    /// assert!(rk.state().iter().all(|v| v.is_finite()));
    /// # Ok::<(), intrinsic_beam::BeamError>(())
    /// ```
    pub fn new(problem: BeamProblem, state: Vec<f64>, kinematics: Kinematics) -> Result<Self> {
        problem.validate()?;
        let beam = &problem.beam;
        check_len("initial state", beam.dim(), state.len())?;
        check_len("kinematics nodes", beam.n_nodes(), kinematics.xi.len())?;
        let k = beam.k();
        let comps = beam.components();
        for &i in comps.indices() {
            if beam.section().rigid[i] || beam.section().massless[i] {
                return Err(BeamError::NotAnOde {
                    reason: format!("direction {i} is rigid or massless (algebraic rows)"),
                });
            }
        }
        let m_red = DMatrix::from_fn(k, k, |a, b| comps.entry(&beam.section().mass, a, b));
        let c_red = DMatrix::from_fn(k, k, |a, b| comps.entry(&beam.section().compliance, a, b));
        let inv = |m: DMatrix<f64>, what: &str| {
            m.cholesky()
                .map(|c| c.inverse())
                .ok_or_else(|| BeamError::LinearSolve { reason: format!("{what} not invertible") })
        };
        Ok(Self {
            m_inv: inv(m_red.clone(), "M")?,
            c_inv: inv(c_red, "C")?,
            m_red,
            problem,
            state,
            kinematics,
            time: 0.0,
        })
    }

    /// Current state.
    pub fn state(&self) -> &[f64] {
        &self.state
    }

    /// Current kinematics.
    pub fn kinematics(&self) -> &Kinematics {
        &self.kinematics
    }

    /// Current time.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Applies end conditions at time `t` to `x` (force end values, prescribed velocities);
    /// returns the prescribed velocity rates per (node-unknown, rate).
    fn apply_ends(&self, t: f64, x: &mut [f64]) -> Vec<(usize, f64)> {
        let p = &self.problem;
        let k = p.beam.k();
        let mut rates = Vec::new();
        let delta = 1e-6;
        for end in [End::Left, End::Right] {
            for a in 0..k {
                let u = p.end_unknown(end, a);
                // end_target(time, dt) evaluates at time + dt (velocity) or time + dt/2 (force):
                // pass dt = 0 to evaluate at t.
                x[u] = p.end_target(end, a, t, 0.0);
                if u < k * p.beam.n_nodes() {
                    let rate = (p.end_target(end, a, t + delta, 0.0)
                        - p.end_target(end, a, t - delta, 0.0))
                        / (2.0 * delta);
                    rates.push((u, rate));
                }
            }
        }
        rates
    }

    /// Rates of the beam vector and kinematics at `(t, x, kin)`; `x` gets end values applied.
    fn rates(
        &self,
        t: f64,
        x: &mut [f64],
        kin: &Kinematics,
    ) -> (Vec<f64>, Vec<Vector4<f64>>, Vec<Vector3<f64>>) {
        let beam: &Beam = &self.problem.beam;
        let k = beam.k();
        let prescribed = self.apply_ends(t, x);
        let rot: Vec<Matrix3<f64>> = kin.xi.iter().map(rotation).collect();
        let (loads, _) = beam.node_loads(t, &self.problem.loads, &rot);
        let mut f = vec![0.0; beam.n_rows()];
        beam.rhs(x, &loads, &mut f);
        let mut dx = vec![0.0; beam.dim()];
        for node in 0..beam.n_nodes() {
            let w = beam.mesh().weights()[node];
            let s = node * k;
            let fixed: Vec<(usize, f64)> = prescribed
                .iter()
                .filter(|(u, _)| *u >= s && *u < s + k)
                .map(|&(u, r)| (u - s, r))
                .collect();
            let rhs = DVector::from_fn(k, |a, _| f[s + a] / w);
            let sol = if fixed.is_empty() {
                &self.m_inv * rhs
            } else {
                // M ẋ = f/w + reactions on fixed components: solve for the free ones
                let free: Vec<usize> =
                    (0..k).filter(|a| !fixed.iter().any(|(b, _)| b == a)).collect();
                let mut out = DVector::zeros(k);
                for &(b, r) in &fixed {
                    out[b] = r;
                }
                if !free.is_empty() {
                    let mff = DMatrix::from_fn(free.len(), free.len(), |i, j| {
                        self.m_red[(free[i], free[j])]
                    });
                    let r = DVector::from_fn(free.len(), |i, _| {
                        rhs[free[i]]
                            - fixed
                                .iter()
                                .map(|&(b, rate)| self.m_red[(free[i], b)] * rate)
                                .sum::<f64>()
                    });
                    let y = mff
                        .cholesky()
                        .map(|c| c.solve(&r))
                        .unwrap_or_else(|| DVector::from_element(free.len(), f64::NAN));
                    for (i, &a) in free.iter().enumerate() {
                        out[a] = y[i];
                    }
                }
                out
            };
            for a in 0..k {
                dx[s + a] = sol[a];
            }
        }
        for e in 0..beam.n_elements() {
            let h = beam.mesh().lengths()[e];
            let s = beam.x2_index(e, 0);
            let rhs = DVector::from_fn(k, |a, _| f[s + a] / h);
            let sol = &self.c_inv * rhs;
            for a in 0..k {
                dx[s + a] = sol[a];
            }
        }
        let mut dxi = Vec::with_capacity(beam.n_nodes());
        let mut dr = Vec::with_capacity(beam.n_nodes());
        for node in 0..beam.n_nodes() {
            let (v, w) = halves(&beam.x1(x, node));
            dxi.push(u_matrix(&w) * kin.xi[node]);
            dr.push(rot[node] * v);
        }
        (dx, dxi, dr)
    }

    /// One RK4 step of size `dt`.
    pub fn step(&mut self, dt: f64) -> Result<()> {
        if !crate::error::positive_finite(dt) {
            return Err(BeamError::NonPositiveTime { field: "dt".into(), value: dt });
        }
        let n = self.state.len();
        let t = self.time;
        let stage = |base: &[f64],
                     kin: &Kinematics,
                     d: &(Vec<f64>, Vec<Vector4<f64>>, Vec<Vector3<f64>>),
                     c: f64| {
            let x: Vec<f64> = (0..n).map(|i| base[i] + c * d.0[i]).collect();
            let kin = Kinematics {
                xi: kin.xi.iter().zip(&d.1).map(|(a, b)| a + b * c).collect(),
                r: kin.r.iter().zip(&d.2).map(|(a, b)| a + b * c).collect(),
            };
            (x, kin)
        };
        let mut x0 = self.state.clone();
        let k1 = self.rates(t, &mut x0, &self.kinematics);
        let (mut x, kin) = stage(&x0, &self.kinematics, &k1, 0.5 * dt);
        let k2 = self.rates(t + 0.5 * dt, &mut x, &kin);
        let (mut x, kin) = stage(&x0, &self.kinematics, &k2, 0.5 * dt);
        let k3 = self.rates(t + 0.5 * dt, &mut x, &kin);
        let (mut x, kin) = stage(&x0, &self.kinematics, &k3, dt);
        let k4 = self.rates(t + dt, &mut x, &kin);
        let comb = |a: f64, b: f64, c: f64, d: f64| (a + 2.0 * b + 2.0 * c + d) * dt / 6.0;
        let mut new: Vec<f64> =
            (0..n).map(|i| x0[i] + comb(k1.0[i], k2.0[i], k3.0[i], k4.0[i])).collect();
        for node in 0..self.kinematics.xi.len() {
            let xi = self.kinematics.xi[node]
                + (k1.1[node] + k2.1[node] * 2.0 + k3.1[node] * 2.0 + k4.1[node]) * (dt / 6.0);
            self.kinematics.xi[node] = xi.normalize();
            self.kinematics.r[node] +=
                (k1.2[node] + k2.2[node] * 2.0 + k3.2[node] * 2.0 + k4.2[node]) * (dt / 6.0);
        }
        self.apply_ends(t + dt, &mut new);
        if new.iter().any(|v| !v.is_finite()) {
            return Err(BeamError::NonFiniteState {
                what: "RK4 step (step size beyond stability?)".into(),
            });
        }
        self.state = new;
        self.time += dt;
        Ok(())
    }
}
