//! [`Record`]: one message the daemon took in, as the journal stores it.
//!
//! Payload layout (little-endian; see docs/state.md):
//! `tag: u8 | frontend: u32 | sequence: u64 | body`, with the body
//!
//! | tag | record      | body |
//! |-----|-------------|------|
//! | 1   | keyframe    | `id: u64, has_guess: u8, x, y, θ: f64` |
//! | 2   | edge        | `from, to: u64, kind: u8, x, y, θ: f64, Ω upper: 6 × f64` |
//! | 3   | fix         | `keyframe: u64, lat, lon, height: f64, covariance: 4 × f64` |
//! | 4   | refused     | none: refused on arrival, it only counts for the acknowledgement |
//! | 5   | keyframe 3-D | `id: u64, has_guess: u8, x, y, z, qx, qy, qz, qw: f64` |
//! | 6   | edge 3-D    | `from, to: u64, kind: u8, x, y, z, qx, qy, qz, qw: f64, Ω upper: 21 × f64` |
//! | 7   | fix with a held height | a fix's body, then `height variance: f64` |
//!
//! A record of the other dimension than the reader's is an error
//! ([`StoreError::Dimension`]), never a torn tail to cut off.

use super::bytes::{Get, Put};
use super::StoreError;
use slamd_protocol::codec::Origin;
use slamd_types::{
    EdgeInput, EdgeKind, FixInput, Geodetic, InformationMatrix, KeyframeInput, Pose2, RigidMotion,
};

/// One message the daemon took in; `P` is the pose type of the map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Record<P: RigidMotion = Pose2> {
    /// A keyframe.
    Keyframe(Origin, KeyframeInput<P>),
    /// An edge.
    Edge(Origin, EdgeInput<P>),
    /// A GPS fix.
    Fix(Origin, FixInput),
    /// A message refused on arrival.
    Refused(Origin),
}

const KEYFRAME: u8 = 1;
const EDGE: u8 = 2;
const FIX: u8 = 3;
const REFUSED: u8 = 4;
const KEYFRAME3: u8 = 5;
const EDGE3: u8 = 6;
const FIX_HEIGHT: u8 = 7;
/// A keyframe with a timestamp: the keyframe's payload, then the `u64`.
const KEYFRAME_AT: u8 = 8;
const KEYFRAME3_AT: u8 = 9;

/// The tags of a keyframe and an edge in `dimension`.
fn tags(dimension: u32) -> (u8, u8) {
    if dimension == 3 {
        (KEYFRAME3, EDGE3)
    } else {
        (KEYFRAME, EDGE)
    }
}

/// The tag of a keyframe with a timestamp in `dimension`.
fn stamped_tag(dimension: u32) -> u8 {
    if dimension == 3 {
        KEYFRAME3_AT
    } else {
        KEYFRAME_AT
    }
}

impl<P: RigidMotion> Record<P> {
    /// Who sent it.
    pub fn origin(&self) -> Origin {
        match *self {
            Record::Keyframe(o, _) | Record::Edge(o, _) | Record::Fix(o, _) | Record::Refused(o) => o,
        }
    }

    /// Appends the payload.
    pub fn encode(&self, p: &mut Put) {
        let (keyframe, edge) = tags(P::DIMENSION);
        let (tag, o) = match self {
            Record::Keyframe(o, k) if k.timestamp_ns == 0 => (keyframe, o),
            Record::Keyframe(o, _) => (stamped_tag(P::DIMENSION), o),
            Record::Edge(o, _) => (edge, o),
            Record::Fix(o, f) if f.height_variance.is_some() => (FIX_HEIGHT, o),
            Record::Fix(o, _) => (FIX, o),
            Record::Refused(o) => (REFUSED, o),
        };
        p.u8(tag);
        p.u32(o.frontend);
        p.u64(o.sequence);
        match self {
            Record::Keyframe(_, k) => {
                p.u64(k.id);
                p.u8(u8::from(k.guess.is_some()));
                put_pose(p, &k.guess.unwrap_or(P::IDENTITY));
                if k.timestamp_ns != 0 {
                    p.u64(k.timestamp_ns);
                }
            }
            Record::Edge(_, e) => put_edge(p, e),
            Record::Fix(_, f) => {
                put_fix(p, f);
                if let Some(v) = f.height_variance {
                    p.f64(v);
                }
            }
            Record::Refused(_) => {}
        }
    }

    /// Reads a payload; every field is checked as on the wire.
    pub fn decode(bytes: &[u8]) -> Result<Record<P>, StoreError> {
        let mut g = Get::new(bytes);
        let tag = g.u8()?;
        let o = Origin {
            frontend: g.u32()?,
            sequence: g.u64()?,
        };
        let (keyframe, edge) = tags(P::DIMENSION);
        let stamped = stamped_tag(P::DIMENSION);
        let r = match tag {
            KEYFRAME | EDGE | KEYFRAME3 | EDGE3 | KEYFRAME_AT | KEYFRAME3_AT
                if tag != keyframe && tag != edge && tag != stamped =>
            {
                return Err(StoreError::Dimension {
                    found: 5 - P::DIMENSION,
                    serving: P::DIMENSION,
                })
            }
            t if t == keyframe || t == stamped => {
                let id = g.u64()?;
                let has = g.u8()?;
                let pose = get_pose(&mut g)?;
                let timestamp_ns = if t == stamped { g.u64()? } else { 0 };
                let guess = (has != 0).then_some(pose);
                Record::Keyframe(
                    o,
                    KeyframeInput {
                        id,
                        guess,
                        timestamp_ns,
                    },
                )
            }
            t if t == edge => Record::Edge(o, get_edge(&mut g)?),
            FIX => Record::Fix(o, get_fix(&mut g, false)?),
            FIX_HEIGHT => Record::Fix(o, get_fix(&mut g, true)?),
            REFUSED => Record::Refused(o),
            t => return Err(StoreError::Malformed(format!("unknown record tag {t}"))),
        };
        g.finish()?;
        Ok(r)
    }
}

/// `keyframe, lat, lon, height, covariance` (without the height's
/// variance).
/// The first format version whose edges mean what their writer wrote.
pub(super) const AS_WRITTEN: u32 = 4;

/// An edge read from a file of format `version`, in the meaning the
/// daemon that wrote the file gave it. Before [`AS_WRITTEN`] slamd turned
/// an edge written newer-id-first, `(i, j, Z, Ω)` with `i > j`, into
/// `(j, i, Z⁻¹, Ω)`, information kept, and solved that; such an edge is
/// turned the same way here, so that an old journal or map goes on
/// meaning the graph it was solved as. Every other edge is unchanged.
pub(super) fn edge_of_version<P: RigidMotion>(e: EdgeInput<P>, version: u32) -> EdgeInput<P> {
    if version >= AS_WRITTEN || e.from < e.to {
        return e;
    }
    EdgeInput {
        from: e.to,
        to: e.from,
        measurement: e.measurement.inverse(),
        ..e
    }
}

impl<P: RigidMotion> Record<P> {
    /// The record read from a file of format `version`, in this version's
    /// meaning ([`edge_of_version`]).
    pub(super) fn of_version(self, version: u32) -> Self {
        match self {
            Record::Edge(o, e) => Record::Edge(o, edge_of_version(e, version)),
            r => r,
        }
    }
}

pub(super) fn put_fix(p: &mut Put, f: &FixInput) {
    p.u64(f.keyframe);
    p.f64s(&[f.position.lat, f.position.lon, f.position.height]);
    p.f64s(&f.covariance);
}

/// A fix as [`put_fix`] wrote it, then its height's variance if
/// `height_variance`; checked as on the wire.
pub(super) fn get_fix(g: &mut Get<'_>, height_variance: bool) -> Result<FixInput, StoreError> {
    let keyframe = g.u64()?;
    let [lat, lon, height] = g.f64s()?;
    let covariance = g.f64s()?;
    let bad = |e: &dyn std::fmt::Display| StoreError::Malformed(format!("fix on keyframe {keyframe}: {e}"));
    let position = Geodetic::new(lat, lon, height).map_err(|e| bad(&e))?;
    let fix = FixInput {
        keyframe,
        position,
        covariance,
        height_variance: if height_variance { Some(g.f64()?) } else { None },
    };
    if covariance.iter().any(|c| !c.is_finite()) || fix.height_variance.is_some_and(|v| !v.is_finite()) {
        return Err(bad(&"not finite"));
    }
    Ok(fix)
}

/// A pose's [`RigidMotion::PARAMS`] numbers.
pub(super) fn put_pose<P: RigidMotion>(p: &mut Put, pose: &P) {
    let mut v = [0.0; 7];
    pose.write_params(&mut v);
    p.f64s(&v[..P::PARAMS]);
}

/// `from, to, kind, measurement, Ω upper`.
pub(super) fn put_edge<P: RigidMotion>(p: &mut Put, e: &EdgeInput<P>) {
    p.u64(e.from);
    p.u64(e.to);
    p.u8(match e.kind {
        EdgeKind::Odometry => 0,
        EdgeKind::LoopClosure => 1,
        EdgeKind::Other => 2,
        EdgeKind::TrustedLoopClosure => 3,
    });
    put_pose(p, &e.measurement);
    let mut upper = [0.0; 21];
    e.information.write_upper(&mut upper);
    p.f64s(&upper[..P::Information::UPPER]);
}

pub(super) fn get_edge<P: RigidMotion>(g: &mut Get<'_>) -> Result<EdgeInput<P>, StoreError> {
    let from = g.u64()?;
    let to = g.u64()?;
    let kind = match g.u8()? {
        0 => EdgeKind::Odometry,
        1 => EdgeKind::LoopClosure,
        2 => EdgeKind::Other,
        3 => EdgeKind::TrustedLoopClosure,
        k => {
            return Err(StoreError::Malformed(format!(
                "edge {from}→{to}: unknown kind {k}"
            )))
        }
    };
    let measurement = get_pose(g)?;
    let mut upper = [0.0; 21];
    g.f64s_into(&mut upper[..P::Information::UPPER])?;
    let information = P::Information::from_upper_slice(&upper)
        .map_err(|e| StoreError::Malformed(format!("edge {from}→{to}: {e}")))?;
    Ok(EdgeInput::new(from, to, measurement, information, kind))
}

pub(super) fn get_pose<P: RigidMotion>(g: &mut Get<'_>) -> Result<P, StoreError> {
    let mut v = [0.0; 7];
    g.f64s_into(&mut v[..P::PARAMS])?;
    P::from_params(&v).ok_or_else(|| {
        StoreError::Malformed(format!(
            "pose {:?} is not finite or not of unit norm",
            &v[..P::PARAMS]
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use slamd_types::{Information, Information6, Pose3};

    pub(crate) fn samples() -> Vec<Record> {
        let o = |s| Origin {
            frontend: 7,
            sequence: s,
        };
        let info = Information::from_upper([10.0, 1.0, 0.0, 20.0, 0.5, 30.0]).unwrap();
        vec![
            Record::Keyframe(o(1), KeyframeInput::new(0, None, 0)),
            Record::Keyframe(
                o(2),
                KeyframeInput::new(1, Some(Pose2::new(1.0, -2.0, 0.5)), 1_700_000_000_123_456_789),
            ),
            Record::Edge(
                o(3),
                EdgeInput::new(0, 1, Pose2::new(1.0, 0.1, -0.2), info, EdgeKind::LoopClosure),
            ),
            Record::Fix(
                o(4),
                FixInput {
                    keyframe: 1,
                    position: Geodetic {
                        lat: 45.5,
                        lon: 9.2,
                        height: 120.0,
                    },
                    covariance: [4.0, 0.1, 0.1, 9.0],
                    height_variance: None,
                },
            ),
            Record::Fix(
                o(6),
                FixInput {
                    keyframe: 1,
                    position: Geodetic {
                        lat: 45.5,
                        lon: 9.2,
                        height: 121.0,
                    },
                    covariance: [4.0, 0.0, 0.0, 4.0],
                    height_variance: Some(9.0),
                },
            ),
            Record::Refused(o(5)),
        ]
    }

    #[test]
    fn every_record_reads_back_as_written() {
        for r in samples() {
            let mut p = Put::default();
            r.encode(&mut p);
            assert_eq!(Record::decode(&p.0).unwrap(), r);
            // one byte short or one too many is refused
            assert!(Record::<Pose2>::decode(&p.0[..p.0.len() - 1]).is_err());
            p.u8(0);
            assert!(Record::<Pose2>::decode(&p.0).is_err());
        }
    }

    #[test]
    fn a_nan_or_a_bad_information_is_refused() {
        let mut p = Put::default();
        samples()[2].encode(&mut p);
        // the measurement's x sits after tag, origin, from, to and kind
        let x = 1 + 4 + 8 + 8 + 8 + 1;
        let mut bad = p.0.clone();
        bad[x..x + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        assert!(
            matches!(Record::<Pose2>::decode(&bad), Err(StoreError::Malformed(m)) if m.contains("not finite"))
        );
        let mut bad = p.0.clone();
        bad[x + 24..x + 32].copy_from_slice(&(-1.0f64).to_le_bytes());
        assert!(Record::<Pose2>::decode(&bad).is_err());
    }

    #[test]
    fn spatial_records_read_back_and_the_other_dimension_is_refused() {
        let o = Origin {
            frontend: 3,
            sequence: 1,
        };
        let z = Pose3::from_xyz_rpy([1.0, 2.0, -0.5, 0.1, 0.2, -0.3]);
        let info = Information6::identity().scaled(2.0);
        for r in [
            Record::Keyframe(o, KeyframeInput::new(4, Some(z), 0)),
            Record::Keyframe(o, KeyframeInput::new(5, None, 42)),
            Record::Edge(o, EdgeInput::new(4, 5, z, info, EdgeKind::LoopClosure)),
        ] {
            let mut p = Put::default();
            r.encode(&mut p);
            let back = Record::<Pose3>::decode(&p.0).unwrap();
            match (r, back) {
                (Record::Edge(_, a), Record::Edge(_, b)) => {
                    assert_eq!(
                        (a.from, a.to, a.kind, a.information),
                        (b.from, b.to, b.kind, b.information)
                    );
                    assert!((a.measurement.translation - b.measurement.translation).norm() < 1e-15);
                    assert!(a.measurement.rotation.angle_to(&b.measurement.rotation) < 1e-12);
                }
                (Record::Keyframe(_, a), Record::Keyframe(_, b)) => {
                    assert_eq!(
                        (a.id, a.guess.map(|g| g.translation), a.timestamp_ns),
                        (b.id, b.guess.map(|g| g.translation), b.timestamp_ns)
                    );
                }
                _ => panic!("{back:?} is not {r:?}"),
            }
            let err = Record::<Pose2>::decode(&p.0).unwrap_err();
            assert!(
                matches!(err, StoreError::Dimension { found: 3, serving: 2 }),
                "{err}"
            );
        }
        let mut p = Put::default();
        samples()[2].encode(&mut p);
        let err = Record::<Pose3>::decode(&p.0).unwrap_err();
        assert!(
            matches!(err, StoreError::Dimension { found: 2, serving: 3 }),
            "{err}"
        );
    }
}
