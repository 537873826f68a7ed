//! Node quaternions and positions: integrated in time with the midpoint rate (eqs. 7, 10) and
//! rebuilt in space from strains (eqs. 7, 10 in `s`).
//!
//! Time: `ξ⁺ = exp(dt U(ω_mid)) ξ`, `r⁺ = r + dt T(ξ_mid) v_mid` with
//! `ξ_mid = exp(dt/2 U(ω_mid)) ξ` (theory.md §2–3). Space: along element `e` with strains
//! `[γ, κ] = C x2_e`, `ξ_{e+1} = exp(h_e U(κ + κ0)) ξ_e` and
//! `r_{e+1} = r_e + h_e T(ξ_{e+½}) (e1 + γ)` — the same midpoint rule, with `s` for `t`.

use nalgebra::{UnitQuaternion, Vector3, Vector4, Vector6};

use crate::beam::Beam;
use crate::error::{check_len, BeamError, Result};
use crate::operators::halves;
use crate::rotation::{quaternion_half_and_full_step, quaternion_step, rotation};

/// Quaternion `ξ_n = [ξ0, ξv]` and position `r_n` (global frame) of every node.
#[derive(Clone, Debug, PartialEq)]
pub struct Kinematics {
    /// Unit quaternions, scalar first; `T(ξ)` maps local to global components.
    pub xi: Vec<Vector4<f64>>,
    /// Positions.
    pub r: Vec<Vector3<f64>>,
}

impl Kinematics {
    /// The reference configuration of `beam` (strain-free, with its initial curvature `κ0`),
    /// node 0 at `r0` with orientation `xi0`.
    pub fn reference(beam: &Beam, xi0: Vector4<f64>, r0: Vector3<f64>) -> Result<Self> {
        let zero = vec![0.0; beam.dim()];
        Self::from_strains(beam, &zero, xi0, r0)
    }

    /// A straight beam along global e1 from the origin (identity orientation, `κ0` applied).
    ///
    /// ```
    /// use intrinsic_beam::{Beam, Components, Kinematics, Mesh, Section};
    ///
    /// let beam = Beam::new(Section::paper_2d(), Mesh::uniform(1.0, 4)?, Components::Planar)?;
    /// let kin = Kinematics::straight(&beam);
    /// assert_eq!(kin.r.len(), 5); // node positions along e1
    /// assert!((kin.r[4].x - 1.0).abs() < 1e-15);
    /// # Ok::<(), intrinsic_beam::BeamError>(())
    /// ```
    pub fn straight(beam: &Beam) -> Self {
        Self::reference(beam, Vector4::new(1.0, 0.0, 0.0, 0.0), Vector3::zeros())
            .expect("the zero state has the right size")
    }

    /// Rebuilds quaternions and positions in space from the strains of `state` (eqs. 7, 10),
    /// starting from `xi0`, `r0` at node 0.
    pub fn from_strains(
        beam: &Beam,
        state: &[f64],
        xi0: Vector4<f64>,
        r0: Vector3<f64>,
    ) -> Result<Self> {
        check_len("state", beam.dim(), state.len())?;
        let norm = xi0.norm();
        if !crate::error::positive_finite(norm) {
            return Err(BeamError::NonFinite {
                field: "root quaternion".into(),
                index: "norm".into(),
                value: norm,
            });
        }
        let c = &beam.section().compliance;
        let kappa0 = beam.section().kappa0;
        let mut xi = vec![xi0 / norm];
        let mut r = vec![r0];
        for (e, &h) in beam.mesh().lengths().iter().enumerate() {
            let strain = c * beam.x2(state, e);
            let (gamma, kappa) = halves(&strain);
            let curv = kappa + kappa0;
            let x = xi[e];
            let x_mid = quaternion_step(&x, &curv, 0.5 * h);
            r.push(r[e] + rotation(&x_mid) * (Vector3::x() + gamma) * h);
            xi.push(quaternion_step(&x, &curv, h));
        }
        Ok(Self { xi, r })
    }

    /// Advances by one implicit-midpoint step from `old` to `new` (midpoint velocities, see
    /// [`Beam::midpoint`]).
    pub fn advance(&mut self, beam: &Beam, old: &[f64], new: &[f64], dt: f64) -> Result<()> {
        check_len("kinematics nodes", beam.n_nodes(), self.xi.len())?;
        check_len("old state", beam.dim(), old.len())?;
        check_len("new state", beam.dim(), new.len())?;
        let k = beam.k();
        let mut mid = [0.0; 6];
        for n in 0..beam.n_nodes() {
            // node velocities at the midpoint (`Beam::midpoint` restricted to x1_n)
            for (a, m) in mid.iter_mut().enumerate().take(k) {
                let i = beam.x1_index(n, a);
                let w = beam.midpoint_weight(i);
                *m = w * new[i] + (1.0 - w) * old[i];
            }
            self.advance_node(n, &beam.components().embed(&mid[..k]), dt);
        }
        Ok(())
    }

    /// Advances node `n` by `dt` with the velocities `x1 = [v, ω]` held constant.
    #[inline]
    fn advance_node(&mut self, n: usize, x1: &Vector6<f64>, dt: f64) {
        let (v, w) = halves(x1);
        let (x_mid, x_new) = quaternion_half_and_full_step(&self.xi[n], &w, dt);
        self.r[n] += rotation(&x_mid) * v * dt;
        self.xi[n] = x_new;
    }

    /// Advances by `dt` with the node velocities of `rates` (a beam vector) held constant.
    pub fn advance_with_rates(&mut self, beam: &Beam, rates: &[f64], dt: f64) -> Result<()> {
        check_len("rates", beam.dim(), rates.len())?;
        for n in 0..beam.n_nodes() {
            self.advance_node(n, &beam.x1(rates, n), dt);
        }
        Ok(())
    }

    /// Rotation angle (rad) between the orientations of node `a` here and node `b` in `other`
    /// (panics if a node index is out of range).
    pub fn angle_between(&self, a: usize, other: &Self, b: usize) -> f64 {
        let qa = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            self.xi[a][0],
            self.xi[a][1],
            self.xi[a][2],
            self.xi[a][3],
        ));
        let qb = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            other.xi[b][0],
            other.xi[b][1],
            other.xi[b][2],
            other.xi[b][3],
        ));
        qa.angle_to(&qb)
    }

    /// Largest position distance between corresponding nodes (over the common nodes).
    pub fn max_position_gap(&self, other: &Self) -> f64 {
        self.r.iter().zip(&other.r).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max)
    }
}
