//! GPS positions: [`Geodetic`] (WGS84) and the checks every fix passes.

/// Why a GPS fix was refused.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum GpsError {
    /// A NaN or infinite number.
    NonFinite,
    /// |lat| > 90° or |lon| > 180°.
    OutOfRange,
    /// The covariance is not symmetric positive definite.
    NotPositiveDefinite,
}

impl std::fmt::Display for GpsError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            GpsError::NonFinite => "GPS fix has a non-finite number",
            GpsError::OutOfRange => "GPS fix is out of range (|lat| > 90 or |lon| > 180)",
            GpsError::NotPositiveDefinite => "GPS covariance is not positive definite",
        })
    }
}

impl std::error::Error for GpsError {}

/// Checks a 2×2 covariance (row-major): finite, symmetric, positive definite.
pub fn check_covariance(c: [f64; 4]) -> Result<(), GpsError> {
    if c.iter().any(|v| !v.is_finite()) {
        return Err(GpsError::NonFinite);
    }
    let sym = (c[1] - c[2]).abs() <= 1e-12 * c[0].abs().max(c[3].abs()).max(1e-300);
    if !(sym && c[0] > 0.0 && c[0] * c[3] - c[1] * c[2] > 0.0) {
        return Err(GpsError::NotPositiveDefinite);
    }
    Ok(())
}

/// A WGS84 position: degrees, degrees, metres above the ellipsoid. In
/// configuration files it is the string `"LAT,LON"` or `"LAT,LON,HEIGHT"`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Geodetic {
    /// Latitude (degrees, north positive).
    pub lat: f64,
    /// Longitude (degrees, east positive).
    pub lon: f64,
    /// Height above the ellipsoid (m).
    pub height: f64,
}

impl Geodetic {
    /// A checked position: finite, |lat| ≤ 90, |lon| ≤ 180.
    pub fn new(lat: f64, lon: f64, height: f64) -> Result<Self, GpsError> {
        if !(lat.is_finite() && lon.is_finite() && height.is_finite()) {
            return Err(GpsError::NonFinite);
        }
        if lat.abs() > 90.0 || lon.abs() > 180.0 {
            return Err(GpsError::OutOfRange);
        }
        Ok(Self { lat, lon, height })
    }

    /// Parses `LAT,LON` or `LAT,LON,HEIGHT` (degrees, metres).
    pub fn parse(s: &str) -> Result<Self, String> {
        let v: Vec<f64> = s
            .split(',')
            .map(|t| {
                t.trim()
                    .parse::<f64>()
                    .map_err(|_| format!("`{t}` is not a number"))
            })
            .collect::<Result<_, _>>()?;
        let (lat, lon, h) = match v[..] {
            [lat, lon] => (lat, lon, 0.0),
            [lat, lon, h] => (lat, lon, h),
            _ => return Err(format!("`{s}`: expected LAT,LON or LAT,LON,HEIGHT")),
        };
        Self::new(lat, lon, h).map_err(|e| format!("`{s}`: {e}"))
    }
}

impl TryFrom<String> for Geodetic {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        Self::parse(&s)
    }
}

impl From<Geodetic> for String {
    fn from(g: Geodetic) -> String {
        format!("{},{},{}", g.lat, g.lon, g.height)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_positions_are_refused() {
        assert_eq!(Geodetic::new(91.0, 0.0, 0.0), Err(GpsError::OutOfRange));
        assert_eq!(Geodetic::new(0.0, -180.5, 0.0), Err(GpsError::OutOfRange));
        assert_eq!(Geodetic::new(f64::NAN, 0.0, 0.0), Err(GpsError::NonFinite));
        assert_eq!(Geodetic::parse("45.5,9.2").unwrap().lat, 45.5);
        assert!(Geodetic::parse("45.5").is_err());
    }

    #[test]
    fn covariances_must_be_symmetric_positive_definite() {
        assert_eq!(check_covariance([1.0, 0.0, 0.0, 2.0]), Ok(()));
        assert_eq!(
            check_covariance([1.0, 0.0, 0.0, f64::NAN]),
            Err(GpsError::NonFinite)
        );
        assert_eq!(
            check_covariance([1.0, 2.0, 2.0, 1.0]),
            Err(GpsError::NotPositiveDefinite)
        );
        assert_eq!(
            check_covariance([1.0, 0.5, 0.0, 1.0]),
            Err(GpsError::NotPositiveDefinite)
        );
        assert_eq!(
            check_covariance([-1.0, 0.0, 0.0, 1.0]),
            Err(GpsError::NotPositiveDefinite)
        );
    }
}
