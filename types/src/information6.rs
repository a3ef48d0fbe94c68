//! [`Information6`]: the inverse covariance Ω of a 3-D edge measurement.
//!
//! The error of a 3-D edge is `[Δt, Δq_xyz]` (g2o's EdgeSE3), so Ω is 6×6
//! over `(x, y, z, qx, qy, qz)`. It is stored as the upper triangle row by
//! row, g2o's 21 numbers in g2o's order. Every constructor checks that the
//! matrix is finite and positive definite.

use crate::InformationError;
use nalgebra::{Matrix3, Matrix6, Vector6};

/// A symmetric positive-definite 6×6 information matrix over
/// `(x, y, z, qx, qy, qz)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Information6 {
    matrix: Matrix6<f64>,
}

impl Information6 {
    /// From the upper triangle, row by row (g2o's `EDGE_SE3:QUAT` order).
    pub fn from_upper(upper: [f64; 21]) -> Result<Self, InformationError> {
        let mut m = Matrix6::zeros();
        let mut k = 0;
        for r in 0..6 {
            for c in r..6 {
                m[(r, c)] = upper[k];
                m[(c, r)] = upper[k];
                k += 1;
            }
        }
        Self::from_matrix(&m)
    }

    /// From a full matrix; only the upper triangle is read.
    pub fn from_matrix(m: &Matrix6<f64>) -> Result<Self, InformationError> {
        let mut s = *m;
        for r in 0..6 {
            for c in 0..r {
                s[(r, c)] = s[(c, r)];
            }
        }
        if s.iter().any(|v| !v.is_finite()) {
            return Err(InformationError::NonFinite);
        }
        if s.cholesky().is_none() {
            return Err(InformationError::NotPositiveDefinite);
        }
        Ok(Self { matrix: s })
    }

    /// From iSAM's square-root information: the upper-triangular `R`, row
    /// by row, with `Ω = RᵀR` (over iSAM's own error ordering).
    pub fn from_sqrt_upper(r: [f64; 21]) -> Result<Self, InformationError> {
        if r.iter().any(|v| !v.is_finite()) {
            return Err(InformationError::NonFinite);
        }
        let mut rm = Matrix6::zeros();
        let mut k = 0;
        for row in 0..6 {
            for c in row..6 {
                rm[(row, c)] = r[k];
                k += 1;
            }
        }
        Self::from_matrix(&(rm.transpose() * rm))
    }

    /// Ω over roll, pitch, yaw errors carried over to the quaternion-vector
    /// error: near the identity the angles are twice the quaternion's
    /// vector, so `Ω_q = D Ω_rpy D` with `D = diag(1, 1, 1, 2, 2, 2)`.
    pub fn from_rpy_information(m: &Matrix6<f64>) -> Result<Self, InformationError> {
        let d = Vector6::new(1.0, 1.0, 1.0, 2.0, 2.0, 2.0);
        let scaled = Matrix6::from_fn(|r, c| d[r] * m[(r, c)] * d[c]);
        Self::from_matrix(&scaled)
    }

    /// The identity (unit information).
    pub fn identity() -> Self {
        Self {
            matrix: Matrix6::identity(),
        }
    }

    /// The upper triangle, row by row.
    pub fn upper(&self) -> [f64; 21] {
        let mut u = [0.0; 21];
        let mut k = 0;
        for r in 0..6 {
            for c in r..6 {
                u[k] = self.matrix[(r, c)];
                k += 1;
            }
        }
        u
    }

    /// The full symmetric matrix Ω.
    pub fn matrix(&self) -> &Matrix6<f64> {
        &self.matrix
    }

    /// The covariance Σ = Ω⁻¹.
    pub fn covariance(&self) -> Matrix6<f64> {
        self.matrix
            .cholesky()
            .map(|c| c.inverse())
            .unwrap_or_else(|| Matrix6::from_diagonal_element(f64::INFINITY))
    }

    /// The quadratic form `eᵀ Ω e`.
    pub fn mahalanobis(&self, e: &[f64; 6]) -> f64 {
        let v = Vector6::from_column_slice(e);
        v.dot(&(self.matrix * v))
    }

    /// Isotropic weight of the rotation: `3 / tr Σ_R`, with `Σ_R` the
    /// marginal covariance of the quaternion-vector error, turned into one
    /// of the rotation-vector error (twice as large, so four times the
    /// variance).
    pub fn rotation_weight(&self) -> f64 {
        let c = self.covariance();
        3.0 / (4.0 * (c[(3, 3)] + c[(4, 4)] + c[(5, 5)]))
    }

    /// Isotropic weight of the translation: `3 / tr Σ_t`.
    pub fn translation_weight(&self) -> f64 {
        let c = self.covariance();
        3.0 / (c[(0, 0)] + c[(1, 1)] + c[(2, 2)])
    }

    /// The marginal translation information `(Σ_t)⁻¹`.
    pub fn translation_information(&self) -> Matrix3<f64> {
        let c = self.covariance().fixed_view::<3, 3>(0, 0).into_owned();
        c.try_inverse().unwrap_or_else(Matrix3::zeros)
    }

    /// Ω scaled by `s > 0`.
    pub fn scaled(&self, s: f64) -> Self {
        Self {
            matrix: self.matrix * s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_upper_triangle_is_read_row_by_row() {
        let mut u = [0.0; 21];
        u[0] = 10.0; // xx
        u[1] = 1.0; // xy
        u[6] = 20.0; // yy
        u[11] = 30.0; // zz
        u[15] = 40.0; // qx qx
        u[18] = 50.0; // qy qy
        u[19] = 2.0; // qy qz
        u[20] = 60.0; // qz qz
        let i = Information6::from_upper(u).unwrap();
        let m = i.matrix();
        assert_eq!(
            (m[(0, 1)], m[(1, 0)], m[(4, 5)], m[(5, 4)], m[(3, 3)]),
            (1.0, 1.0, 2.0, 2.0, 40.0)
        );
        assert_eq!(i.upper(), u);
        // eᵀΩe with e = (1, 0, 0, 0, 1, 1): 10 + 50 + 60 + 2·2
        assert!((i.mahalanobis(&[1.0, 0.0, 0.0, 0.0, 1.0, 1.0]) - 124.0).abs() < 1e-12);
    }

    #[test]
    fn rejects_nan_and_indefinite() {
        let mut u = Information6::identity().upper();
        u[3] = f64::NAN;
        assert_eq!(Information6::from_upper(u), Err(InformationError::NonFinite));
        let mut u = Information6::identity().upper();
        u[1] = 2.0;
        assert_eq!(
            Information6::from_upper(u),
            Err(InformationError::NotPositiveDefinite)
        );
        let mut u = Information6::identity().upper();
        u[20] = 0.0;
        assert_eq!(
            Information6::from_upper(u),
            Err(InformationError::NotPositiveDefinite)
        );
    }

    #[test]
    fn square_roots_and_angles_are_carried_over() {
        let mut r = [0.0; 21];
        for (k, v) in [(0, 2.0), (6, 2.0), (11, 2.0), (15, 10.0), (18, 10.0), (20, 10.0)] {
            r[k] = v;
        }
        let i = Information6::from_sqrt_upper(r).unwrap();
        assert_eq!(i.matrix()[(0, 0)], 4.0);
        assert_eq!(i.matrix()[(5, 5)], 100.0);
        let q = Information6::from_rpy_information(i.matrix()).unwrap();
        assert_eq!((q.matrix()[(0, 0)], q.matrix()[(5, 5)]), (4.0, 400.0));
        // 3 / (4 tr Σ_q) with Σ_q = diag(1/400): the rotation-vector weight 100
        assert!((q.rotation_weight() - 100.0).abs() < 1e-9);
        assert!((q.translation_weight() - 4.0).abs() < 1e-12);
    }
}
