//! Between slamd's input types ([`slamd_types`]) and the protocol's
//! messages, both ways: `*_out` encodes what a frontend sends, `*_in`
//! decodes and checks what the daemon receives.
//!
//! Inbound, every field is checked before it reaches the engine: a
//! non-finite number, an information matrix that is not positive definite,
//! an unknown edge kind or another protocol version becomes a typed
//! [`Rejection`] with its reason in words, never a panic and never a NaN in
//! the graph.

// A Rejection is the message the daemon publishes for refused input; it is
// built once per refusal, so its size in a Result does not matter.
#![allow(clippy::result_large_err)]

use crate::message::kind;
use crate::{Edge, EdgeKindWire, GpsFix, Keyframe, Rejection, RejectionReason, PROTOCOL_VERSION};
use slamd_types::{
    check_covariance, EdgeInput, EdgeKind, FixInput, Geodetic, GpsError, Information, InformationError,
    KeyframeId, Pose2,
};

/// Who sent a message and its number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Origin {
    /// The frontend.
    pub frontend: u32,
    /// Its message number.
    pub sequence: u64,
}

/// A rejection of message `message` (a [`kind`] constant) from `o`.
pub fn reject(o: Origin, message: u32, reason: RejectionReason, ids: [u64; 2], text: &str) -> Rejection {
    Rejection::new(o.frontend, o.sequence, message, reason, ids, text)
}

fn check_version(o: Origin, message: u32, protocol: u32, ids: [u64; 2]) -> Result<(), Rejection> {
    if protocol == PROTOCOL_VERSION {
        Ok(())
    } else {
        Err(reject(
            o,
            message,
            RejectionReason::ProtocolVersion,
            ids,
            &format!("message speaks protocol {protocol}, the daemon {PROTOCOL_VERSION}"),
        ))
    }
}

/// A keyframe message as the engine takes it: id and optional guess.
pub fn keyframe_in(m: &Keyframe) -> Result<(Origin, KeyframeId, Option<Pose2>), Rejection> {
    let o = Origin {
        frontend: m.frontend,
        sequence: m.sequence,
    };
    check_version(o, kind::KEYFRAME, m.protocol, [m.id, 0])?;
    let guess = (m.has_guess != 0).then(|| Pose2::new(m.guess[0], m.guess[1], m.guess[2]));
    if guess.is_some_and(|g| !g.is_finite()) {
        return Err(reject(
            o,
            kind::KEYFRAME,
            RejectionReason::NonFinite,
            [m.id, 0],
            &format!("keyframe {}: guess has a non-finite coordinate", m.id),
        ));
    }
    Ok((o, m.id, guess))
}

/// An edge message as the engine takes it.
pub fn edge_in(m: &Edge) -> Result<(Origin, EdgeInput), Rejection> {
    let o = Origin {
        frontend: m.frontend,
        sequence: m.sequence,
    };
    let ids = [m.from, m.to];
    check_version(o, kind::EDGE, m.protocol, ids)?;
    let bad = |reason, text: String| Err(reject(o, kind::EDGE, reason, ids, &text));
    let kind = match EdgeKindWire::from_u32(m.kind) {
        Some(EdgeKindWire::Odometry) => EdgeKind::Odometry,
        Some(EdgeKindWire::LoopClosure) => EdgeKind::LoopClosure,
        Some(EdgeKindWire::Other) => EdgeKind::Other,
        Some(EdgeKindWire::TrustedLoopClosure) => EdgeKind::TrustedLoopClosure,
        None => {
            return bad(
                RejectionReason::BadKind,
                format!("edge {}→{}: unknown kind {}", m.from, m.to, m.kind),
            )
        }
    };
    if m.from == m.to {
        return bad(
            RejectionReason::SelfEdge,
            format!("edge from keyframe {} to itself", m.from),
        );
    }
    let measurement = Pose2::new(m.dx, m.dy, m.dtheta);
    if !measurement.is_finite() {
        return bad(
            RejectionReason::NonFinite,
            format!("edge {}→{}: non-finite measurement", m.from, m.to),
        );
    }
    let information = match Information::from_upper(m.information) {
        Ok(i) => i,
        Err(InformationError::NonFinite) => {
            return bad(
                RejectionReason::NonFinite,
                format!("edge {}→{}: non-finite information", m.from, m.to),
            )
        }
        Err(_) => {
            return bad(
                RejectionReason::NotPositiveDefinite,
                format!(
                    "edge {}→{}: information matrix is not positive definite",
                    m.from, m.to
                ),
            )
        }
    };
    Ok((o, EdgeInput::new(m.from, m.to, measurement, information, kind)))
}

/// A GPS fix message as the engine takes it.
pub fn gps_in(m: &GpsFix) -> Result<(Origin, FixInput), Rejection> {
    let o = Origin {
        frontend: m.frontend,
        sequence: m.sequence,
    };
    let ids = [m.keyframe, 0];
    check_version(o, kind::GPS, m.protocol, ids)?;
    let height = if m.has_altitude != 0 { m.altitude } else { 0.0 };
    let position = Geodetic::new(m.latitude, m.longitude, height);
    let checked = position.and_then(|p| check_covariance(m.covariance).map(|_| p));
    match checked {
        Ok(position) => Ok((
            o,
            FixInput {
                keyframe: m.keyframe,
                position,
                covariance: m.covariance,
            },
        )),
        Err(e) => {
            let reason = gps_reason(&e);
            let text = format!(
                "fix on keyframe {} at ({}, {}): {e}",
                m.keyframe, m.latitude, m.longitude
            );
            Err(reject(o, kind::GPS, reason, ids, &text))
        }
    }
}

/// The rejection reason for a refused GPS fix.
pub fn gps_reason(e: &GpsError) -> RejectionReason {
    match e {
        GpsError::NonFinite => RejectionReason::NonFinite,
        GpsError::OutOfRange => RejectionReason::OutOfRange,
        _ => RejectionReason::NotPositiveDefinite,
    }
}

/// A GPS fix message from the frontend's side.
pub fn gps_out(f: &FixInput, o: Origin) -> GpsFix {
    GpsFix {
        keyframe: f.keyframe,
        latitude: f.position.lat,
        longitude: f.position.lon,
        altitude: f.position.height,
        covariance: f.covariance,
        has_altitude: 1,
        frontend: o.frontend,
        sequence: o.sequence,
        protocol: PROTOCOL_VERSION,
        reserved: 0,
    }
}

/// A keyframe message from the frontend's side.
pub fn keyframe_out(id: KeyframeId, timestamp_ns: u64, guess: Option<Pose2>, o: Origin) -> Keyframe {
    Keyframe {
        id,
        timestamp_ns,
        guess: guess.map_or([0.0; 3], |g| g.to_array()),
        has_guess: u32::from(guess.is_some()),
        frontend: o.frontend,
        sequence: o.sequence,
        protocol: PROTOCOL_VERSION,
        reserved: 0,
    }
}

/// An edge message from the frontend's side.
pub fn edge_out(e: &EdgeInput, o: Origin) -> Edge {
    Edge {
        from: e.from,
        to: e.to,
        dx: e.measurement.x,
        dy: e.measurement.y,
        dtheta: e.measurement.theta,
        information: e.information.upper(),
        kind: match e.kind {
            EdgeKind::Odometry => EdgeKindWire::Odometry,
            EdgeKind::LoopClosure => EdgeKindWire::LoopClosure,
            EdgeKind::Other => EdgeKindWire::Other,
            EdgeKind::TrustedLoopClosure => EdgeKindWire::TrustedLoopClosure,
        } as u32,
        frontend: o.frontend,
        sequence: o.sequence,
        protocol: PROTOCOL_VERSION,
        reserved: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge() -> Edge {
        let input = EdgeInput::new(
            1,
            2,
            Pose2::new(1.0, 0.0, 0.1),
            Information::identity(),
            EdgeKind::LoopClosure,
        );
        edge_out(
            &input,
            Origin {
                frontend: 7,
                sequence: 9,
            },
        )
    }

    fn fix(lat: f64, cov: [f64; 4]) -> GpsFix {
        let input = FixInput {
            keyframe: 4,
            position: Geodetic {
                lat,
                lon: 9.2,
                height: 0.0,
            },
            covariance: cov,
        };
        gps_out(
            &input,
            Origin {
                frontend: 1,
                sequence: 3,
            },
        )
    }

    #[test]
    fn fixes_are_checked() {
        let (_, f) = gps_in(&fix(45.5, [1.0, 0.0, 0.0, 1.0])).unwrap();
        assert_eq!((f.keyframe, f.position.lat), (4, 45.5));
        let reason = |m: GpsFix| RejectionReason::from_u32(gps_in(&m).unwrap_err().reason);
        assert_eq!(
            reason(fix(91.0, [1.0, 0.0, 0.0, 1.0])),
            RejectionReason::OutOfRange
        );
        assert_eq!(
            reason(fix(f64::NAN, [1.0, 0.0, 0.0, 1.0])),
            RejectionReason::NonFinite
        );
        assert_eq!(
            reason(fix(45.5, [1.0, 0.0, 0.0, -1.0])),
            RejectionReason::NotPositiveDefinite
        );
        let mut old = fix(45.5, [1.0, 0.0, 0.0, 1.0]);
        old.protocol = PROTOCOL_VERSION - 1;
        assert_eq!(reason(old), RejectionReason::ProtocolVersion);
    }

    #[test]
    fn edges_round_trip() {
        let (o, back) = edge_in(&edge()).unwrap();
        assert_eq!(
            o,
            Origin {
                frontend: 7,
                sequence: 9
            }
        );
        assert_eq!(back.measurement, Pose2::new(1.0, 0.0, 0.1));
        assert_eq!(back.kind, EdgeKind::LoopClosure);
        // every kind survives the wire, the trusted mark included
        for kind in [
            EdgeKind::Odometry,
            EdgeKind::LoopClosure,
            EdgeKind::TrustedLoopClosure,
            EdgeKind::Other,
        ] {
            let sent = EdgeInput { kind, ..back };
            assert_eq!(edge_in(&edge_out(&sent, o)).unwrap().1.kind, kind);
        }
    }

    #[test]
    fn hostile_edges_get_typed_reasons() {
        type Case = (fn(&mut Edge), RejectionReason, &'static str);
        let cases: [Case; 6] = [
            (
                |e| e.dx = f64::NAN,
                RejectionReason::NonFinite,
                "edge 1→2: non-finite measurement",
            ),
            (
                |e| e.information[5] = f64::INFINITY,
                RejectionReason::NonFinite,
                "edge 1→2: non-finite information",
            ),
            (
                |e| e.information = [1.0, 5.0, 0.0, 1.0, 0.0, 1.0],
                RejectionReason::NotPositiveDefinite,
                "edge 1→2: information matrix is not positive definite",
            ),
            (
                |e| e.kind = 42,
                RejectionReason::BadKind,
                "edge 1→2: unknown kind 42",
            ),
            (
                |e| e.to = 1,
                RejectionReason::SelfEdge,
                "edge from keyframe 1 to itself",
            ),
            (
                |e| e.protocol = 99,
                RejectionReason::ProtocolVersion,
                "message speaks protocol 99, the daemon 3",
            ),
        ];
        for (break_it, reason, text) in cases {
            let mut e = edge();
            break_it(&mut e);
            let r = edge_in(&e).unwrap_err();
            assert_eq!((r.reason(), r.text()), (reason, text));
            assert_eq!((r.frontend, r.sequence), (7, 9));
        }
    }

    #[test]
    fn keyframe_guess_must_be_finite() {
        let mut k = keyframe_out(
            5,
            0,
            Some(Pose2::new(1.0, 2.0, 0.0)),
            Origin {
                frontend: 1,
                sequence: 1,
            },
        );
        assert_eq!(keyframe_in(&k).unwrap().2, Some(Pose2::new(1.0, 2.0, 0.0)));
        k.guess[2] = f64::NAN;
        assert_eq!(keyframe_in(&k).unwrap_err().reason(), RejectionReason::NonFinite);
    }
}
