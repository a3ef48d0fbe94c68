//! [`Record`]: one message the daemon took in, as the journal stores it.
//!
//! Payload layout (little-endian; see docs/daemon.md, "State directory"):
//! `tag: u8 | frontend: u32 | sequence: u64 | body`, with the body
//!
//! | tag | record   | body |
//! |-----|----------|------|
//! | 1   | keyframe | `id: u64, has_guess: u8, x, y, θ: f64` |
//! | 2   | edge     | `from, to: u64, kind: u8, x, y, θ: f64, Ω upper: 6 × f64` |
//! | 3   | fix      | `keyframe: u64, lat, lon, height: f64, covariance: 4 × f64` |
//! | 4   | refused  | none: refused on arrival, it only counts for the acknowledgement |

use super::bytes::{Get, Put};
use super::StoreError;
use slamd_protocol::codec::Origin;
use slamd_types::{EdgeInput, EdgeKind, FixInput, Geodetic, Information, KeyframeId, Pose2};

/// One message the daemon took in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Record {
    /// A keyframe and its guess.
    Keyframe(Origin, KeyframeId, Option<Pose2>),
    /// An edge.
    Edge(Origin, EdgeInput),
    /// A GPS fix.
    Fix(Origin, FixInput),
    /// A message refused on arrival.
    Refused(Origin),
}

const KEYFRAME: u8 = 1;
const EDGE: u8 = 2;
const FIX: u8 = 3;
const REFUSED: u8 = 4;

impl Record {
    /// Who sent it.
    pub fn origin(&self) -> Origin {
        match *self {
            Record::Keyframe(o, ..) | Record::Edge(o, _) | Record::Fix(o, _) | Record::Refused(o) => o,
        }
    }

    /// Appends the payload.
    pub fn encode(&self, p: &mut Put) {
        let (tag, o) = match self {
            Record::Keyframe(o, ..) => (KEYFRAME, o),
            Record::Edge(o, _) => (EDGE, o),
            Record::Fix(o, _) => (FIX, o),
            Record::Refused(o) => (REFUSED, o),
        };
        p.u8(tag);
        p.u32(o.frontend);
        p.u64(o.sequence);
        match self {
            Record::Keyframe(_, id, guess) => {
                p.u64(*id);
                p.u8(u8::from(guess.is_some()));
                p.f64s(&guess.unwrap_or(Pose2::IDENTITY).to_array());
            }
            Record::Edge(_, e) => put_edge(p, e),
            Record::Fix(_, f) => {
                p.u64(f.keyframe);
                p.f64s(&[f.position.lat, f.position.lon, f.position.height]);
                p.f64s(&f.covariance);
            }
            Record::Refused(_) => {}
        }
    }

    /// Reads a payload; every field is checked as on the wire.
    pub fn decode(bytes: &[u8]) -> Result<Record, StoreError> {
        let mut g = Get::new(bytes);
        let tag = g.u8()?;
        let o = Origin {
            frontend: g.u32()?,
            sequence: g.u64()?,
        };
        let r = match tag {
            KEYFRAME => {
                let id = g.u64()?;
                let has = g.u8()?;
                let pose = get_pose(&mut g)?;
                Record::Keyframe(o, id, (has != 0).then_some(pose))
            }
            EDGE => Record::Edge(o, get_edge(&mut g)?),
            FIX => {
                let keyframe = g.u64()?;
                let [lat, lon, height] = g.f64s()?;
                let covariance = g.f64s()?;
                let position = Geodetic::new(lat, lon, height)
                    .map_err(|e| StoreError::Malformed(format!("fix on keyframe {keyframe}: {e}")))?;
                if covariance.iter().any(|c| !c.is_finite()) {
                    return Err(StoreError::Malformed(format!(
                        "fix on keyframe {keyframe}: not finite"
                    )));
                }
                Record::Fix(
                    o,
                    FixInput {
                        keyframe,
                        position,
                        covariance,
                    },
                )
            }
            REFUSED => Record::Refused(o),
            t => return Err(StoreError::Malformed(format!("unknown record tag {t}"))),
        };
        g.finish()?;
        Ok(r)
    }
}

/// `from, to, kind, measurement, Ω upper`.
pub(super) fn put_edge(p: &mut Put, e: &EdgeInput) {
    p.u64(e.from);
    p.u64(e.to);
    p.u8(match e.kind {
        EdgeKind::Odometry => 0,
        EdgeKind::LoopClosure => 1,
        EdgeKind::Other => 2,
        EdgeKind::TrustedLoopClosure => 3,
    });
    p.f64s(&e.measurement.to_array());
    p.f64s(&e.information.upper());
}

pub(super) fn get_edge(g: &mut Get<'_>) -> Result<EdgeInput, StoreError> {
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
    let information = Information::from_upper(g.f64s()?)
        .map_err(|e| StoreError::Malformed(format!("edge {from}→{to}: {e}")))?;
    Ok(EdgeInput::new(from, to, measurement, information, kind))
}

pub(super) fn get_pose(g: &mut Get<'_>) -> Result<Pose2, StoreError> {
    let [x, y, theta] = g.f64s()?;
    let p = Pose2::new(x, y, theta);
    if p.is_finite() {
        Ok(p)
    } else {
        Err(StoreError::Malformed(format!(
            "pose ({x}, {y}, {theta}) is not finite"
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn samples() -> Vec<Record> {
        let o = |s| Origin {
            frontend: 7,
            sequence: s,
        };
        let info = Information::from_upper([10.0, 1.0, 0.0, 20.0, 0.5, 30.0]).unwrap();
        vec![
            Record::Keyframe(o(1), 0, None),
            Record::Keyframe(o(2), 1, Some(Pose2::new(1.0, -2.0, 0.5))),
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
            assert!(Record::decode(&p.0[..p.0.len() - 1]).is_err());
            p.u8(0);
            assert!(Record::decode(&p.0).is_err());
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
        assert!(matches!(Record::decode(&bad), Err(StoreError::Malformed(m)) if m.contains("not finite")));
        let mut bad = p.0.clone();
        bad[x + 24..x + 32].copy_from_slice(&(-1.0f64).to_le_bytes());
        assert!(Record::decode(&bad).is_err());
    }
}
