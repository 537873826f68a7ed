//! The discrete energy identity of one step (theory.md §2), for checks: the residual rows
//! paired with the midpoint unknowns against the energy change less the midpoint powers.

use super::{Beam, StepInput, StepPower};
use crate::error::Result;

/// The two sides of the discrete energy identity of a step from `old` to `new`:
/// `Σ_i mid_i R_i = (ε(new) − ε(old))/dt − (boundary + load + damping power)`, which holds to
/// round-off for *any* pair of states (the identity behind exact energy conservation).
#[derive(Clone, Copy, Debug)]
pub struct EnergyBalance {
    /// `Σ_i mid_i R_i`: the step residual rows paired with the midpoint unknowns.
    pub work: f64,
    /// `Σ_i |mid_i R_i|`: the size of the terms of `work` (the scale of its round-off).
    pub terms: f64,
    /// `(ε(new) − ε(old))/dt`.
    pub energy_rate: f64,
    /// The powers at the step midpoint.
    pub power: StepPower,
}

impl EnergyBalance {
    /// The right-hand side `(ε(new) − ε(old))/dt − boundary − loads − damping`.
    pub fn rate(&self) -> f64 {
        self.energy_rate - self.power.boundary - self.power.loads - self.power.damping
    }

    /// `|work − rate|`: zero up to round-off.
    pub fn defect(&self) -> f64 {
        (self.work - self.rate()).abs()
    }
}

impl Beam {
    /// Both sides of the discrete energy identity of the step `old → new` (see
    /// [`EnergyBalance`]).
    ///
    /// ```
    /// use intrinsic_beam::samples::random::{random_section, random_vec, seeded};
    /// use intrinsic_beam::{Beam, Components, Kinematics, Loads, Mesh, StepInput};
    ///
    /// let mut rng = seeded(1);
    /// let section = random_section(&mut rng, Components::Spatial, true, true);
    /// let beam = Beam::new(section, Mesh::uniform(1.0, 4)?, Components::Spatial)?;
    /// let (old, new) = (random_vec(&mut rng, beam.dim()), random_vec(&mut rng, beam.dim()));
    /// let kin = Kinematics::straight(&beam);
    /// let loads = Loads::none();
    /// let input = StepInput { time: 0.0, dt: 0.01, loads: &loads, node_quaternions: &kin.xi };
    /// let b = beam.energy_balance(&input, &old, &new)?;
    /// assert!(b.defect() <= 1e-12 * b.terms);
    /// # Ok::<(), intrinsic_beam::BeamError>(())
    /// ```
    pub fn energy_balance(
        &self,
        input: &StepInput<'_>,
        old: &[f64],
        new: &[f64],
    ) -> Result<EnergyBalance> {
        let mut res = vec![0.0; self.n_rows()];
        self.step_residual(input, old, new, &mut res)?;
        let mut mid = vec![0.0; self.dim()];
        self.midpoint(old, new, &mut mid)?;
        let work: f64 = res.iter().zip(&mid).map(|(r, m)| r * m).sum();
        let terms: f64 = res.iter().zip(&mid).map(|(r, m)| (r * m).abs()).sum();
        let power = self.step_power(input, old, new)?;
        let energy_rate = (self.energy(new)? - self.energy(old)?) / input.dt;
        Ok(EnergyBalance { work, terms, energy_rate, power })
    }
}
