//! Cross-section properties: mass `M`, compliance `C`, initial curvature `κ0`, damping `D0, D1, D2`.
//!
//! Components are ordered `[1,2,3 | 1,2,3]` (`x1 = [v, ω]`, `x2 = [f, m]`, theory.md §1).
//! A *rigid* direction `i` has zero compliance (row and column `i` of `C` are zero): its force
//! component is a reaction and its strain is zero. A *massless* direction `i` has zero inertia
//! (row and column `i` of `M` are zero): its velocity equation is algebraic. Both are stated
//! explicitly in [`Section::rigid`] / [`Section::massless`]; [`Section::validate`] checks that
//! the matrices agree and that `M`, `C` are positive definite on the remaining directions.
//! Rigid/massless directions are coordinate directions by design: the implicit integrator then
//! knows exactly which rows are algebraic.
//!
//! Damping enters eq. (1) as written in the paper, on the right-hand side:
//! `… = D0 x1 + D1 ∂s x1 + D2 ∂ss x1 + f1`. Hence a dissipative `D0` is negative semidefinite
//! and a dissipative `D2` positive semidefinite (the diffusion `D2 ∂ss` removes energy).

use nalgebra::{DMatrix, Matrix6, SymmetricEigen, Vector3};

use crate::error::{check_finite, BeamError, Result};

/// Relative tolerance used for symmetry and zero-direction checks (round-off of input data).
const SYMMETRY_TOLERANCE: f64 = 1e-12;

/// Sectional properties of a beam (constant along the beam).
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    /// Sectional mass matrix `M` (6×6, symmetric positive semidefinite).
    pub mass: Matrix6<f64>,
    /// Sectional compliance matrix `C = K⁻¹` (6×6, symmetric positive semidefinite).
    pub compliance: Matrix6<f64>,
    /// Rigid directions: `rigid[i]` ⇔ row/column `i` of `C` is zero.
    pub rigid: [bool; 6],
    /// Massless directions: `massless[i]` ⇔ row/column `i` of `M` is zero.
    pub massless: [bool; 6],
    /// Initial curvature and twist `κ0` (local frame), enters `E` (eq. 3).
    pub kappa0: Vector3<f64>,
    /// Nodal (viscous) damping `D0` of eq. (1); dissipative when its symmetric part is ≤ 0.
    pub d0: Matrix6<f64>,
    /// First-derivative damping `D1` of eq. (1) (energy-neutral in the interior when symmetric).
    pub d1: Matrix6<f64>,
    /// Diffusive damping `D2` of eq. (1), symmetric positive semidefinite.
    pub d2: Matrix6<f64>,
}

impl Section {
    /// A section from diagonal mass and *stiffness* entries: `stiffness[i] = f64::INFINITY`
    /// states a rigid direction (compliance 0), `mass[i] = 0` a massless one. No curvature,
    /// no damping. Validated.
    ///
    /// ```
    /// use intrinsic_beam::Section;
    ///
    /// // m = 1, EI = 1 in bending about e2; a zero stiffness would be an error
    /// let s = Section::from_diagonals([1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4], [1e4, 1e4, 1e4, 0.5, 1.0, 1.0])?;
    /// assert!(Section::from_diagonals([1.0; 6], [0.0; 6]).is_err());
    /// # let _ = s;
    /// # Ok::<(), intrinsic_beam::BeamError>(())
    /// ```
    pub fn from_diagonals(mass: [f64; 6], stiffness: [f64; 6]) -> Result<Self> {
        let mut m = Matrix6::zeros();
        let mut c = Matrix6::zeros();
        let mut rigid = [false; 6];
        let mut massless = [false; 6];
        for i in 0..6 {
            if stiffness[i] == f64::INFINITY {
                rigid[i] = true;
            } else if stiffness[i].is_nan() || stiffness[i] <= 0.0 {
                return Err(BeamError::NotDefinite {
                    field: "section.stiffness".into(),
                    requirement: format!("positive in direction {i} (use infinity for rigid)"),
                    value: stiffness[i],
                });
            } else {
                c[(i, i)] = 1.0 / stiffness[i];
            }
            check_finite("section.mass", format!("{i}"), mass[i])?;
            if mass[i] == 0.0 {
                massless[i] = true;
            }
            m[(i, i)] = mass[i];
        }
        let s = Self {
            mass: m,
            compliance: c,
            rigid,
            massless,
            kappa0: Vector3::zeros(),
            d0: Matrix6::zeros(),
            d1: Matrix6::zeros(),
            d2: Matrix6::zeros(),
        };
        s.validate()?;
        Ok(s)
    }

    /// Returns the section with initial curvature/twist `κ0` (validated).
    pub fn with_kappa0(mut self, kappa0: Vector3<f64>) -> Result<Self> {
        self.kappa0 = kappa0;
        self.validate()?;
        Ok(self)
    }

    /// Returns the section with damping matrices `D0, D1, D2` of eq. (1) (validated).
    pub fn with_damping(
        mut self,
        d0: Matrix6<f64>,
        d1: Matrix6<f64>,
        d2: Matrix6<f64>,
    ) -> Result<Self> {
        self.d0 = d0;
        self.d1 = d1;
        self.d2 = d2;
        self.validate()?;
        Ok(self)
    }

    /// The paper's 2D section (§5.1, theory.md §9): `M = diag(1, 1, 1, 0, 1e-5, 0)`,
    /// `C⁻¹ = diag(1000, ∞, 1e5, ∞, 1, ∞)`, `D2 = diag(1, 0, 0, 0, 1, 0)·1e-4`.
    /// Rigid: f2, m1, m3; massless: ω1, ω3.
    pub fn paper_2d() -> Self {
        let s = Self::from_diagonals(
            [1.0, 1.0, 1.0, 0.0, 1e-5, 0.0],
            [1000.0, f64::INFINITY, 1e5, f64::INFINITY, 1.0, f64::INFINITY],
        )
        .expect("the paper's 2D section is valid");
        let d2 =
            Matrix6::from_diagonal(&nalgebra::Vector6::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0)) * 1e-4;
        s.with_damping(Matrix6::zeros(), Matrix6::zeros(), d2).expect("valid damping")
    }

    /// The paper's 3D section (§5.3, theory.md §9): `M = diag(1, 1, 1, 2e-4, 1e-4, 1e-4)`,
    /// `C⁻¹ = diag(1000, 1e5, 1e5, 0.05, 1, 2)`, `D2 = diag(1, 0, 0, 1, 1, 1)·1e-4`.
    pub fn paper_3d() -> Self {
        let s = Self::from_diagonals(
            [1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4],
            [1000.0, 1e5, 1e5, 0.05, 1.0, 2.0],
        )
        .expect("the paper's 3D section is valid");
        let d2 =
            Matrix6::from_diagonal(&nalgebra::Vector6::new(1.0, 0.0, 0.0, 1.0, 1.0, 1.0)) * 1e-4;
        s.with_damping(Matrix6::zeros(), Matrix6::zeros(), d2).expect("valid damping")
    }

    /// The paper's sections without damping (for conservation checks).
    pub fn undamped(mut self) -> Self {
        self.d0 = Matrix6::zeros();
        self.d1 = Matrix6::zeros();
        self.d2 = Matrix6::zeros();
        self
    }

    /// Whether any damping matrix is non-zero.
    pub fn has_damping(&self) -> bool {
        self.d0.iter().chain(self.d1.iter()).chain(self.d2.iter()).any(|&x| x != 0.0)
    }

    /// Checks: all entries finite; `M`, `C`, `D2` symmetric; stated rigid/massless directions
    /// have zero rows/columns; `M` (resp. `C`) positive definite on the non-massless (non-rigid)
    /// directions; `D2` positive semidefinite; the symmetric part of `D0` negative semidefinite.
    pub fn validate(&self) -> Result<()> {
        for (name, mat) in [
            ("section.mass", &self.mass),
            ("section.compliance", &self.compliance),
            ("section.d0", &self.d0),
            ("section.d1", &self.d1),
            ("section.d2", &self.d2),
        ] {
            for i in 0..6 {
                for j in 0..6 {
                    check_finite(name, format!("({i},{j})"), mat[(i, j)])?;
                }
            }
        }
        for i in 0..3 {
            check_finite("section.kappa0", format!("{i}"), self.kappa0[i])?;
        }
        for (name, mat) in [
            ("section.mass", &self.mass),
            ("section.compliance", &self.compliance),
            ("section.d2", &self.d2),
        ] {
            check_symmetric(name, mat)?;
        }
        check_directions("section.mass", &self.mass, &self.massless, "massless")?;
        check_directions("section.compliance", &self.compliance, &self.rigid, "rigid")?;
        let keep_m: Vec<usize> = (0..6).filter(|&i| !self.massless[i]).collect();
        check_positive_definite("section.mass", &self.mass, &keep_m, "non-massless")?;
        let keep_c: Vec<usize> = (0..6).filter(|&i| !self.rigid[i]).collect();
        check_positive_definite("section.compliance", &self.compliance, &keep_c, "non-rigid")?;
        let scale_d2 = self.d2.amax().max(f64::MIN_POSITIVE);
        let min_d2 = min_eigenvalue(&self.d2);
        if min_d2 < -SYMMETRY_TOLERANCE * scale_d2 {
            return Err(BeamError::NotDefinite {
                field: "section.d2".into(),
                requirement: "positive semidefinite (dissipative diffusion)".into(),
                value: min_d2,
            });
        }
        let d0s = (self.d0 + self.d0.transpose()) * 0.5;
        let scale_d0 = d0s.amax().max(f64::MIN_POSITIVE);
        let max_d0 = -min_eigenvalue(&(-d0s));
        if max_d0 > SYMMETRY_TOLERANCE * scale_d0 {
            return Err(BeamError::NotDefinite {
                field: "section.d0".into(),
                requirement: "negative semidefinite in its symmetric part (eq. 1 sign: +D0 x1)"
                    .into(),
                value: max_d0,
            });
        }
        Ok(())
    }

    /// `E` of eq. (3) for this section's `κ0`.
    pub fn e_matrix(&self) -> Matrix6<f64> {
        crate::operators::e_matrix(&self.kappa0)
    }
}

fn check_symmetric(field: &str, m: &Matrix6<f64>) -> Result<()> {
    let scale = m.amax();
    for i in 0..6 {
        for j in (i + 1)..6 {
            let (a, b) = (m[(i, j)], m[(j, i)]);
            if (a - b).abs() > SYMMETRY_TOLERANCE * scale {
                return Err(BeamError::NotSymmetric { field: field.into(), row: i, col: j, a, b });
            }
        }
    }
    Ok(())
}

fn check_directions(field: &str, m: &Matrix6<f64>, zero: &[bool; 6], kind: &str) -> Result<()> {
    for i in 0..6 {
        let row_zero = (0..6).all(|j| m[(i, j)] == 0.0 && m[(j, i)] == 0.0);
        if zero[i] && !row_zero {
            return Err(BeamError::InconsistentDirection {
                field: field.into(),
                direction: i,
                problem: format!("is stated {kind} but its row/column is not zero"),
            });
        }
        if !zero[i] && m[(i, i)] == 0.0 {
            return Err(BeamError::InconsistentDirection {
                field: field.into(),
                direction: i,
                problem: format!("has a zero diagonal entry but is not stated {kind}"),
            });
        }
    }
    Ok(())
}

fn check_positive_definite(
    field: &str,
    m: &Matrix6<f64>,
    keep: &[usize],
    which: &str,
) -> Result<()> {
    if keep.is_empty() {
        return Ok(());
    }
    let sub = DMatrix::from_fn(keep.len(), keep.len(), |i, j| m[(keep[i], keep[j])]);
    let min = SymmetricEigen::new(sub.clone()).eigenvalues.min();
    let scale = sub.amax();
    // Positive definite relative to the matrix scale; a relative eigenvalue below 1e-13 is
    // numerically singular and would make the step system singular.
    if min.is_nan() || min <= 1e-13 * scale {
        return Err(BeamError::NotDefinite {
            field: field.into(),
            requirement: format!("positive definite on the {which} directions"),
            value: min,
        });
    }
    Ok(())
}

fn min_eigenvalue(m: &Matrix6<f64>) -> f64 {
    SymmetricEigen::new(*m).eigenvalues.min()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_sections_are_valid() {
        let s2 = Section::paper_2d();
        assert_eq!(s2.rigid, [false, true, false, true, false, true]);
        assert_eq!(s2.massless, [false, false, false, true, false, true]);
        assert!(Section::paper_3d().validate().is_ok());
        assert!(s2.has_damping() && !s2.clone().undamped().has_damping());
    }

    #[test]
    fn nan_is_rejected() {
        let mut s = Section::paper_3d();
        s.mass[(2, 2)] = f64::NAN;
        assert!(matches!(s.validate(), Err(BeamError::NonFinite { .. })));
    }

    #[test]
    fn non_symmetric_is_rejected() {
        let mut s = Section::paper_3d();
        s.compliance[(0, 1)] = 1e-4;
        let err = s.validate().unwrap_err();
        assert!(matches!(err, BeamError::NotSymmetric { row: 0, col: 1, .. }), "{err}");
        assert!(err.to_string().contains("section.compliance"));
    }

    #[test]
    fn indefinite_is_rejected() {
        let mut s = Section::paper_3d();
        s.mass[(0, 1)] = 2.0;
        s.mass[(1, 0)] = 2.0;
        assert!(matches!(s.validate(), Err(BeamError::NotDefinite { .. })));
        let mut s = Section::paper_3d();
        s.d2[(0, 0)] = -1.0;
        assert!(matches!(s.validate(), Err(BeamError::NotDefinite { .. })));
        let mut s = Section::paper_3d();
        s.d0[(0, 0)] = 1.0;
        assert!(matches!(s.validate(), Err(BeamError::NotDefinite { .. })));
        assert!(Section::from_diagonals([1.0; 6], [1.0, -1.0, 1.0, 1.0, 1.0, 1.0]).is_err());
    }

    #[test]
    fn unstated_zero_direction_is_rejected() {
        let mut s = Section::paper_2d();
        s.rigid[1] = false;
        assert!(matches!(s.validate(), Err(BeamError::InconsistentDirection { direction: 1, .. })));
        let mut s = Section::paper_3d();
        s.massless[0] = true;
        assert!(matches!(s.validate(), Err(BeamError::InconsistentDirection { direction: 0, .. })));
    }

    #[test]
    fn full_coupled_matrices_are_allowed() {
        let mut s = Section::paper_3d();
        s.compliance[(0, 4)] = 1e-3;
        s.compliance[(4, 0)] = 1e-3;
        s.mass[(1, 5)] = 1e-3;
        s.mass[(5, 1)] = 1e-3;
        assert!(s.validate().is_ok());
    }
}
