//! [`Information`]: the inverse covariance Ω of an edge measurement.
//!
//! Stored as the upper triangle in g2o's order `[xx, xy, xθ, yy, yθ, θθ]`.
//! Every constructor checks that the matrix is finite and positive definite,
//! so a NaN never reaches the solver.

use nalgebra::Matrix3;
use std::fmt;

/// Why a set of numbers is not a valid information matrix.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum InformationError {
    /// An entry is NaN or infinite.
    NonFinite,
    /// The matrix is not positive definite (a leading minor is ≤ 0).
    NotPositiveDefinite,
}

impl fmt::Display for InformationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            InformationError::NonFinite => f.write_str("information matrix has a non-finite entry"),
            InformationError::NotPositiveDefinite => {
                f.write_str("information matrix is not positive definite")
            }
        }
    }
}

impl std::error::Error for InformationError {}

/// A symmetric positive-definite 3×3 information matrix over `(x, y, θ)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Information {
    upper: [f64; 6],
}

impl Information {
    /// From the upper triangle in g2o's order `[xx, xy, xθ, yy, yθ, θθ]`.
    pub fn from_upper(upper: [f64; 6]) -> Result<Self, InformationError> {
        if upper.iter().any(|v| !v.is_finite()) {
            return Err(InformationError::NonFinite);
        }
        let info = Self { upper };
        if !info.is_positive_definite() {
            return Err(InformationError::NotPositiveDefinite);
        }
        Ok(info)
    }

    /// From TORO's order `[xx, xy, yy, θθ, xθ, yθ]`.
    pub fn from_toro(t: [f64; 6]) -> Result<Self, InformationError> {
        Self::from_upper([t[0], t[1], t[4], t[2], t[5], t[3]])
    }

    /// From iSAM's square-root information: the upper-triangular `R` given as
    /// `[r11, r12, r13, r22, r23, r33]`, with `Ω = RᵀR`.
    pub fn from_sqrt_upper(r: [f64; 6]) -> Result<Self, InformationError> {
        if r.iter().any(|v| !v.is_finite()) {
            return Err(InformationError::NonFinite);
        }
        let rm = Matrix3::new(r[0], r[1], r[2], 0.0, r[3], r[4], 0.0, 0.0, r[5]);
        Self::from_matrix(&(rm.transpose() * rm))
    }

    /// From a diagonal of variances `σx², σy², σθ²`.
    pub fn from_variances(var_x: f64, var_y: f64, var_theta: f64) -> Result<Self, InformationError> {
        Self::from_upper([1.0 / var_x, 0.0, 0.0, 1.0 / var_y, 0.0, 1.0 / var_theta])
    }

    /// From a full matrix; only the upper triangle is read.
    pub fn from_matrix(m: &Matrix3<f64>) -> Result<Self, InformationError> {
        Self::from_upper([m[(0, 0)], m[(0, 1)], m[(0, 2)], m[(1, 1)], m[(1, 2)], m[(2, 2)]])
    }

    /// The identity (unit information), handy in tests.
    pub fn identity() -> Self {
        Self {
            upper: [1.0, 0.0, 0.0, 1.0, 0.0, 1.0],
        }
    }

    /// The upper triangle in g2o's order.
    pub fn upper(&self) -> [f64; 6] {
        self.upper
    }

    /// The full symmetric matrix Ω.
    pub fn matrix(&self) -> Matrix3<f64> {
        let u = &self.upper;
        Matrix3::new(u[0], u[1], u[2], u[1], u[3], u[4], u[2], u[4], u[5])
    }

    /// The covariance Σ = Ω⁻¹.
    pub fn covariance(&self) -> Matrix3<f64> {
        // Positive definite by construction, so the inverse exists.
        self.matrix()
            .try_inverse()
            .unwrap_or_else(|| Matrix3::from_diagonal_element(f64::INFINITY))
    }

    /// The quadratic form `eᵀ Ω e`.
    pub fn mahalanobis(&self, e: &[f64; 3]) -> f64 {
        let u = &self.upper;
        u[0] * e[0] * e[0]
            + u[3] * e[1] * e[1]
            + u[5] * e[2] * e[2]
            + 2.0 * (u[1] * e[0] * e[1] + u[2] * e[0] * e[2] + u[4] * e[1] * e[2])
    }

    /// Weight of the heading: `1/σθ²`, the inverse marginal variance.
    pub fn rotation_weight(&self) -> f64 {
        1.0 / self.covariance()[(2, 2)]
    }

    /// Isotropic weight of the translation: `2 / tr Σ_t`, the inverse of the
    /// mean marginal variance of x and y.
    pub fn translation_weight(&self) -> f64 {
        let c = self.covariance();
        2.0 / (c[(0, 0)] + c[(1, 1)])
    }

    /// True when the marginal translation covariance is a multiple of the
    /// identity (to 1e-12 relative), so that no direction is preferred.
    pub fn translation_is_isotropic(&self) -> bool {
        let c = self.covariance();
        let scale = c[(0, 0)].abs().max(c[(1, 1)].abs());
        (c[(0, 0)] - c[(1, 1)]).abs() <= 1e-12 * scale && c[(0, 1)].abs() <= 1e-12 * scale
    }

    /// One scalar weight for the whole edge: `3 / tr Σ`.
    pub fn scalar_weight(&self) -> f64 {
        3.0 / self.covariance().trace()
    }

    /// Ω scaled by `s > 0` (a robust or switchable weight).
    pub fn scaled(&self, s: f64) -> Self {
        Self {
            upper: self.upper.map(|v| v * s),
        }
    }

    fn is_positive_definite(&self) -> bool {
        let u = &self.upper;
        let m1 = u[0];
        let m2 = u[0] * u[3] - u[1] * u[1];
        let det = self.matrix().determinant();
        m1 > 0.0 && m2 > 0.0 && det > 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toro_order_maps_to_g2o_order() {
        // TORO: xx xy yy tt xt yt
        let i = Information::from_toro([10.0, 1.0, 20.0, 30.0, 2.0, 3.0]).unwrap();
        assert_eq!(i.upper(), [10.0, 1.0, 2.0, 20.0, 3.0, 30.0]);
    }

    #[test]
    fn sqrt_information_is_squared() {
        let i = Information::from_sqrt_upper([50.0, 0.0, 0.0, 50.0, 0.0, 100.0]).unwrap();
        assert_eq!(i.upper(), [2500.0, 0.0, 0.0, 2500.0, 0.0, 10000.0]);
        let j = Information::from_sqrt_upper([2.0, 1.0, 0.0, 3.0, 0.0, 1.0]).unwrap();
        // RᵀR: [4, 2, 0; 2, 1+9, 0; 0, 0, 1]
        assert_eq!(j.upper(), [4.0, 2.0, 0.0, 10.0, 0.0, 1.0]);
    }

    #[test]
    fn rejects_nan_and_indefinite() {
        assert_eq!(
            Information::from_upper([f64::NAN, 0.0, 0.0, 1.0, 0.0, 1.0]),
            Err(InformationError::NonFinite)
        );
        assert_eq!(
            Information::from_upper([1.0, 2.0, 0.0, 1.0, 0.0, 1.0]),
            Err(InformationError::NotPositiveDefinite)
        );
        assert_eq!(
            Information::from_upper([1.0, 0.0, 0.0, 1.0, 0.0, 0.0]),
            Err(InformationError::NotPositiveDefinite)
        );
    }

    #[test]
    fn weights_of_isotropic_information() {
        let i = Information::from_upper([50.0, 0.0, 0.0, 50.0, 0.0, 100.0]).unwrap();
        assert!((i.translation_weight() - 50.0).abs() < 1e-12);
        assert!((i.rotation_weight() - 100.0).abs() < 1e-12);
        assert!((i.mahalanobis(&[1.0, 1.0, 0.5]) - 125.0).abs() < 1e-12);
    }
}
