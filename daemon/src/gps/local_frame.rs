//! The local east-north-up frame.
//!
//! slamd places GPS fixes in the plane tangent to the WGS84 ellipsoid at an
//! origin: x points east, y north, z up (REP-103's ENU). The conversion goes
//! through Earth-centred Earth-fixed coordinates (`map_3d`), so it is exact
//! in the tangent plane: a fix whose ENU coordinates were computed this way
//! comes back to within numerical round-off, at any distance.

pub use slamd_types::Geodetic;

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
}
