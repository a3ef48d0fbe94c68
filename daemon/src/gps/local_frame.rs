//! The local east-north-up frame.
//!
//! slamd places GPS fixes in the plane tangent to the WGS84 ellipsoid at an
//! origin: x points east, y north, z up (REP-103's ENU). The conversion goes
//! through Earth-centred Earth-fixed coordinates (`map_3d`), so it is exact
//! in the tangent plane: a fix whose ENU coordinates were computed this way
//! comes back to within numerical round-off, at any distance.

use super::GpsError;

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

/// The tangent plane at `origin`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalFrame {
    /// The point where east = north = up = 0.
    pub origin: Geodetic,
}

impl LocalFrame {
    /// The frame at `origin`.
    pub fn new(origin: Geodetic) -> Self {
        Self { origin }
    }

    /// `(east, north, up)` of `p` in metres.
    pub fn to_enu(&self, p: &Geodetic) -> (f64, f64, f64) {
        let o = &self.origin;
        map_3d::geodetic2enu(
            p.lat.to_radians(),
            p.lon.to_radians(),
            p.height,
            o.lat.to_radians(),
            o.lon.to_radians(),
            o.height,
            map_3d::Ellipsoid::WGS84,
        )
    }

    /// The geodetic position of `(east, north, up)`.
    pub fn to_geodetic(&self, east: f64, north: f64, up: f64) -> Geodetic {
        let o = &self.origin;
        let (lat, lon, h) = map_3d::enu2geodetic(
            east,
            north,
            up,
            o.lat.to_radians(),
            o.lon.to_radians(),
            o.height,
            map_3d::Ellipsoid::WGS84,
        );
        Geodetic {
            lat: lat.to_degrees(),
            lon: lon.to_degrees(),
            height: h,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enu_round_trips_and_points_the_right_way() {
        let frame = LocalFrame::new(Geodetic::new(45.5138, 9.2110, 0.0).unwrap());
        let north = frame.to_geodetic(0.0, 100.0, 0.0);
        assert!(north.lat > 45.5138 && (north.lon - 9.2110).abs() < 1e-9);
        let east = frame.to_geodetic(100.0, 0.0, 0.0);
        assert!(east.lon > 9.2110);
        for (e, n) in [(3.5, -7.25), (1200.0, 850.0), (-4000.0, 25.0)] {
            let g = frame.to_geodetic(e, n, 0.0);
            let (e2, n2, _) = frame.to_enu(&g);
            assert!(
                (e2 - e).abs() < 1e-6 && (n2 - n).abs() < 1e-6,
                "{e},{n} → {e2},{n2}"
            );
        }
    }

    #[test]
    fn bad_positions_are_refused() {
        assert_eq!(Geodetic::new(91.0, 0.0, 0.0), Err(GpsError::OutOfRange));
        assert_eq!(Geodetic::new(0.0, -180.5, 0.0), Err(GpsError::OutOfRange));
        assert_eq!(Geodetic::new(f64::NAN, 0.0, 0.0), Err(GpsError::NonFinite));
        assert_eq!(Geodetic::parse("45.5,9.2").unwrap().lat, 45.5);
        assert!(Geodetic::parse("45.5").is_err());
    }
}
