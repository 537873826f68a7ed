//! The pointwise operators of eqs. (3)–(4) on `k`-component vectors, behind one trait so the
//! step Jacobian of the step system is written once for planar (`k = 3`, the in-plane
//! restrictions of [`crate::operators::planar_ops`]) and spatial (`k = 6`) beams.

use nalgebra::{SVector, Vector3};

use crate::operators::{e_times, et_times, l1_times, l1t_times, l2_times, planar_ops};

/// `L1(x1) p`, `L2(x2) e`, `L1ᵀ(x1) y`, `E x2`, `Eᵀ x1` on `K`-vectors (all bilinear/linear, so
/// their Jacobians are obtained by applying them to unit vectors).
pub(crate) trait Kernels<const K: usize> {
    /// `L1(x1) p`.
    fn l1_times(&self, x1: &SVector<f64, K>, p: &SVector<f64, K>) -> SVector<f64, K>;
    /// `L2(x2) e`.
    fn l2_times(&self, x2: &SVector<f64, K>, e: &SVector<f64, K>) -> SVector<f64, K>;
    /// `L1ᵀ(x1) y`.
    fn l1t_times(&self, x1: &SVector<f64, K>, y: &SVector<f64, K>) -> SVector<f64, K>;
    /// `E x2`.
    fn e_times(&self, x2: &SVector<f64, K>) -> SVector<f64, K>;
    /// `Eᵀ x1`.
    fn et_times(&self, x1: &SVector<f64, K>) -> SVector<f64, K>;
}

/// Planar operators (`v1, v3, ω2 | f1, f3, m2`, `κ0 = κ e2`).
pub(crate) struct PlanarKernels {
    /// `κ0₂`.
    pub kappa: f64,
}

impl Kernels<3> for PlanarKernels {
    #[inline]
    fn l1_times(&self, x1: &Vector3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        planar_ops::l1_times(x1, p)
    }
    #[inline]
    fn l2_times(&self, x2: &Vector3<f64>, e: &Vector3<f64>) -> Vector3<f64> {
        planar_ops::l2_times(x2, e)
    }
    #[inline]
    fn l1t_times(&self, x1: &Vector3<f64>, y: &Vector3<f64>) -> Vector3<f64> {
        planar_ops::l1t_times(x1, y)
    }
    #[inline]
    fn e_times(&self, x2: &Vector3<f64>) -> Vector3<f64> {
        planar_ops::e_times(self.kappa, x2)
    }
    #[inline]
    fn et_times(&self, x1: &Vector3<f64>) -> Vector3<f64> {
        planar_ops::et_times(self.kappa, x1)
    }
}

/// Spatial operators (all six components).
pub(crate) struct SpatialKernels {
    /// `κ0`.
    pub kappa0: Vector3<f64>,
}

impl Kernels<6> for SpatialKernels {
    #[inline]
    fn l1_times(&self, x1: &SVector<f64, 6>, p: &SVector<f64, 6>) -> SVector<f64, 6> {
        l1_times(x1, p)
    }
    #[inline]
    fn l2_times(&self, x2: &SVector<f64, 6>, e: &SVector<f64, 6>) -> SVector<f64, 6> {
        l2_times(x2, e)
    }
    #[inline]
    fn l1t_times(&self, x1: &SVector<f64, 6>, y: &SVector<f64, 6>) -> SVector<f64, 6> {
        l1t_times(x1, y)
    }
    #[inline]
    fn e_times(&self, x2: &SVector<f64, 6>) -> SVector<f64, 6> {
        e_times(&self.kappa0, x2)
    }
    #[inline]
    fn et_times(&self, x1: &SVector<f64, 6>) -> SVector<f64, 6> {
        et_times(&self.kappa0, x1)
    }
}
