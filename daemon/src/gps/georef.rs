//! [`Georef`]: the rigid motion from the map frame to ENU.
//!
//! The map frame is fixed by the first keyframe; GPS lives in ENU. Fitting
//! `enu = R p + t` to the GPS-tagged poses by least squares (Kabsch in the
//! plane, weighted by each fix's inverse variance) lets every fix act as an
//! absolute position equation in the map frame, and gives every pose an
//! ENU pose.

use crate::geometry::Pose2;
use faer::c64;
use nalgebra::Matrix2;

/// `enu = rotation · p + translation`, with `|rotation| = 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Georef {
    /// The map→ENU rotation as a unit complex number.
    pub rotation: c64,
    /// The ENU position of the map origin.
    pub translation: c64,
    /// The height of the map's `z = 0` in ENU (m): `up = z + self.up`. Fitted
    /// to fixes with a held height, in 3-D only (0 in the plane).
    pub up: f64,
}

impl Georef {
    /// The weighted least-squares fit of `enu ≈ R p + t` over the pairs, or
    /// `None` with fewer than two distinct map positions.
    pub fn fit(pairs: &[(c64, c64, f64)]) -> Option<Georef> {
        let w: f64 = pairs.iter().map(|p| p.2).sum();
        if pairs.len() < 2 || w.is_nan() || w <= 0.0 {
            return None;
        }
        let cm: c64 = pairs.iter().map(|(m, _, wi)| m * wi).sum::<c64>() / w;
        let ce: c64 = pairs.iter().map(|(_, e, wi)| e * wi).sum::<c64>() / w;
        let spread: f64 = pairs.iter().map(|(m, _, wi)| wi * (m - cm).norm_sqr()).sum();
        if spread <= 1e-12 * w {
            return None;
        }
        let s: c64 = pairs
            .iter()
            .map(|(m, e, wi)| (e - ce) * (m - cm).conj() * wi)
            .sum();
        let rotation = if s.norm() > 0.0 {
            s / s.norm()
        } else {
            c64::new(1.0, 0.0)
        };
        Some(Georef {
            rotation,
            translation: ce - rotation * cm,
            up: 0.0,
        })
    }

    /// A map pose in ENU.
    pub fn to_enu(&self, p: &Pose2) -> Pose2 {
        Pose2::from_complex(
            self.rotation * p.position() + self.translation,
            p.theta + self.rotation.arg(),
        )
    }

    /// An ENU point in the map frame.
    pub fn to_map(&self, enu: c64) -> c64 {
        self.rotation.conj() * (enu - self.translation)
    }

    /// An ENU covariance in the map frame: `Rᵀ Σ R`.
    pub fn covariance_to_map(&self, sigma: &Matrix2<f64>) -> Matrix2<f64> {
        let r = Matrix2::new(
            self.rotation.re,
            -self.rotation.im,
            self.rotation.im,
            self.rotation.re,
        );
        r.transpose() * sigma * r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_motion() {
        let truth = Georef {
            rotation: c64::from_polar(1.0, 0.7),
            translation: c64::new(100.0, -30.0),
            up: 0.0,
        };
        let map = [c64::new(0.0, 0.0), c64::new(5.0, 1.0), c64::new(-2.0, 7.0)];
        let pairs: Vec<_> = map
            .iter()
            .map(|&m| (m, truth.rotation * m + truth.translation, 1.0))
            .collect();
        let fit = Georef::fit(&pairs).unwrap();
        assert!((fit.rotation - truth.rotation).norm() < 1e-12);
        assert!((fit.translation - truth.translation).norm() < 1e-9);
        assert!((fit.to_map(pairs[1].1) - map[1]).norm() < 1e-9);
        assert!(Georef::fit(&pairs[..1]).is_none(), "one fix fixes no rotation");
    }
}
