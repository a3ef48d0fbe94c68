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

use crate::message::{kind, INFORMATION_UPPER, POSE_PARAMS};
use crate::{Edge, EdgeKindWire, GpsFix, Keyframe, Rejection, RejectionReason, PROTOCOL_VERSION};
use slamd_types::{
    EdgeInput, EdgeKind, FixInput, Geodetic, GpsError, InformationError, InformationMatrix, KeyframeId,
    KeyframeInput, RigidMotion,
};

/// Who sent a message and its number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Origin {
    /// The frontend.
    pub frontend: u32,
    /// Its message number.
    pub sequence: u64,
}

impl Origin {
    /// No frontend: input given in the process (a file, the embedded
    /// engine, a test).
    pub const LOCAL: Origin = Origin {
        frontend: 0,
        sequence: 0,
    };
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

/// Refuses a message written in another dimension than `P`'s.
fn check_dimension<P: RigidMotion>(
    o: Origin,
    message: u32,
    dimension: u32,
    ids: [u64; 2],
    what: &str,
) -> Result<(), Rejection> {
    if dimension == P::DIMENSION {
        return Ok(());
    }
    let text = format!(
        "{what} is {dimension}-D; this daemon serves {}-D graphs (its `dimension` setting)",
        P::DIMENSION
    );
    Err(reject(o, message, RejectionReason::Dimension, ids, &text))
}

/// A pose written in `v`, or why not: a non-finite number, or (in space)
/// a quaternion off unit norm.
fn pose_in<P: RigidMotion>(v: &[f64; POSE_PARAMS]) -> Result<P, (RejectionReason, &'static str)> {
    if v[..P::PARAMS].iter().any(|x| !x.is_finite()) {
        return Err((RejectionReason::NonFinite, "has a non-finite number"));
    }
    P::from_params(v).ok_or((
        RejectionReason::Other,
        "has a quaternion that is not of unit norm",
    ))
}

/// A keyframe message as the engine takes it: id, optional guess and
/// timestamp.
pub fn keyframe_in<P: RigidMotion>(m: &Keyframe) -> Result<(Origin, KeyframeInput<P>), Rejection> {
    let o = Origin {
        frontend: m.frontend,
        sequence: m.sequence,
    };
    let ids = [m.id, 0];
    check_version(o, kind::KEYFRAME, m.protocol, ids)?;
    check_dimension::<P>(o, kind::KEYFRAME, m.dimension, ids, &format!("keyframe {}", m.id))?;
    let input = |guess| KeyframeInput::new(m.id, guess, m.timestamp_ns);
    if m.has_guess == 0 {
        return Ok((o, input(None)));
    }
    match pose_in(&m.guess) {
        Ok(guess) => Ok((o, input(Some(guess)))),
        Err((reason, why)) => Err(reject(
            o,
            kind::KEYFRAME,
            reason,
            ids,
            &format!("keyframe {}: guess {why}", m.id),
        )),
    }
}

/// An edge message as the engine takes it.
pub fn edge_in<P: RigidMotion>(m: &Edge) -> Result<(Origin, EdgeInput<P>), Rejection> {
    let o = Origin {
        frontend: m.frontend,
        sequence: m.sequence,
    };
    let ids = [m.from, m.to];
    check_version(o, kind::EDGE, m.protocol, ids)?;
    let what = format!("edge {}→{}", m.from, m.to);
    check_dimension::<P>(o, kind::EDGE, m.dimension, ids, &what)?;
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
    let measurement = match pose_in::<P>(&m.measurement) {
        Ok(z) => z,
        Err((RejectionReason::NonFinite, _)) => {
            return bad(
                RejectionReason::NonFinite,
                format!("{what}: non-finite measurement"),
            )
        }
        Err((reason, why)) => return bad(reason, format!("{what}: measurement {why}")),
    };
    let information = match P::Information::from_upper_slice(&m.information) {
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
    let has_altitude = m.has_altitude != 0;
    let height = if has_altitude { m.altitude } else { 0.0 };
    let height_variance = (has_altitude && m.altitude_variance != 0.0).then_some(m.altitude_variance);
    let checked = Geodetic::new(m.latitude, m.longitude, height).and_then(|position| {
        let fix = FixInput {
            keyframe: m.keyframe,
            position,
            covariance: m.covariance,
            height_variance,
        };
        fix.check().map(|_| fix)
    });
    match checked {
        Ok(fix) => Ok((o, fix)),
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
        altitude_variance: f.height_variance.unwrap_or(0.0),
        has_altitude: 1,
        frontend: o.frontend,
        sequence: o.sequence,
        protocol: PROTOCOL_VERSION,
        reserved: 0,
    }
}

/// `p`'s numbers as the wire writes a pose.
fn pose_out<P: RigidMotion>(p: &P) -> [f64; POSE_PARAMS] {
    let mut v = [0.0; POSE_PARAMS];
    p.write_params(&mut v);
    v
}

/// A keyframe message from the frontend's side.
pub fn keyframe_out<P: RigidMotion>(
    id: KeyframeId,
    timestamp_ns: u64,
    guess: Option<P>,
    o: Origin,
) -> Keyframe {
    Keyframe {
        id,
        timestamp_ns,
        guess: guess.as_ref().map_or([0.0; POSE_PARAMS], pose_out),
        has_guess: u32::from(guess.is_some()),
        frontend: o.frontend,
        sequence: o.sequence,
        protocol: PROTOCOL_VERSION,
        dimension: P::DIMENSION,
    }
}

/// An edge message from the frontend's side.
pub fn edge_out<P: RigidMotion>(e: &EdgeInput<P>, o: Origin) -> Edge {
    let mut information = [0.0; INFORMATION_UPPER];
    e.information.write_upper(&mut information);
    Edge {
        from: e.from,
        to: e.to,
        measurement: pose_out(&e.measurement),
        information,
        kind: match e.kind {
            EdgeKind::Odometry => EdgeKindWire::Odometry,
            EdgeKind::LoopClosure => EdgeKindWire::LoopClosure,
            EdgeKind::Other => EdgeKindWire::Other,
            EdgeKind::TrustedLoopClosure => EdgeKindWire::TrustedLoopClosure,
        } as u32,
        frontend: o.frontend,
        sequence: o.sequence,
        protocol: PROTOCOL_VERSION,
        dimension: P::DIMENSION,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slamd_types::{Information, Information6, Pose2, Pose3};

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
            height_variance: None,
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
        // a height's variance travels, and must be positive
        let mut m = fix(45.5, [1.0, 0.0, 0.0, 1.0]);
        m.altitude_variance = 4.0;
        assert_eq!(gps_in(&m).unwrap().1.height_variance, Some(4.0));
        m.altitude_variance = -1.0;
        assert_eq!(reason(m), RejectionReason::NotPositiveDefinite);
        m.altitude_variance = f64::NAN;
        assert_eq!(reason(m), RejectionReason::NonFinite);
        let mut old = fix(45.5, [1.0, 0.0, 0.0, 1.0]);
        old.protocol = PROTOCOL_VERSION - 1;
        assert_eq!(reason(old), RejectionReason::ProtocolVersion);
    }

    #[test]
    fn edges_round_trip() {
        let (o, back) = edge_in::<Pose2>(&edge()).unwrap();
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
            assert_eq!(edge_in::<Pose2>(&edge_out(&sent, o)).unwrap().1.kind, kind);
        }
    }

    #[test]
    fn hostile_edges_get_typed_reasons() {
        type Case = (fn(&mut Edge), RejectionReason, &'static str);
        let cases: [Case; 7] = [
            (
                |e| e.measurement[0] = f64::NAN,
                RejectionReason::NonFinite,
                "edge 1→2: non-finite measurement",
            ),
            (
                |e| e.information[5] = f64::INFINITY,
                RejectionReason::NonFinite,
                "edge 1→2: non-finite information",
            ),
            (
                |e| e.information[..6].copy_from_slice(&[1.0, 5.0, 0.0, 1.0, 0.0, 1.0]),
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
                "message speaks protocol 99, the daemon 6",
            ),
            (
                |e| e.dimension = 3,
                RejectionReason::Dimension,
                "edge 1→2 is 3-D; this daemon serves 2-D graphs (its `dimension` setting)",
            ),
        ];
        for (break_it, reason, text) in cases {
            let mut e = edge();
            break_it(&mut e);
            let r = edge_in::<Pose2>(&e).unwrap_err();
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
        assert_eq!(keyframe_in(&k).unwrap().1.guess, Some(Pose2::new(1.0, 2.0, 0.0)));
        k.guess[2] = f64::NAN;
        assert_eq!(
            keyframe_in::<Pose2>(&k).unwrap_err().reason(),
            RejectionReason::NonFinite
        );
    }

    #[test]
    fn spatial_messages_round_trip_and_are_checked() {
        let o = Origin {
            frontend: 2,
            sequence: 5,
        };
        let z = Pose3::from_xyz_rpy([1.0, -2.0, 0.5, 0.1, -0.2, 0.3]);
        let info = Information6::identity().scaled(4.0);
        let sent = EdgeInput::new(3, 8, z, info, EdgeKind::LoopClosure);
        let m = edge_out(&sent, o);
        assert_eq!(m.dimension, 3);
        let (_, back) = edge_in::<Pose3>(&m).unwrap();
        assert!((back.measurement.translation - z.translation).norm() < 1e-15);
        assert!(back.measurement.rotation.angle_to(&z.rotation) < 1e-12);
        assert_eq!(back.information, info);
        // a 3-D edge at a 2-D daemon, and the other way round
        let r = edge_in::<Pose2>(&m).unwrap_err();
        assert_eq!(r.reason(), RejectionReason::Dimension);
        assert_eq!(
            r.text(),
            "edge 3→8 is 3-D; this daemon serves 2-D graphs (its `dimension` setting)"
        );
        let k = keyframe_out(4, 0, Some(Pose2::new(1.0, 2.0, 0.0)), o);
        assert_eq!(
            keyframe_in::<Pose3>(&k).unwrap_err().text(),
            "keyframe 4 is 2-D; this daemon serves 3-D graphs (its `dimension` setting)"
        );
        // a quaternion far from unit norm is refused, not normalised
        let mut bad = m;
        bad.measurement[6] = 3.0;
        let r = edge_in::<Pose3>(&bad).unwrap_err();
        assert_eq!(
            r.text(),
            "edge 3→8: measurement has a quaternion that is not of unit norm"
        );
        let mut k = keyframe_out(6, 0, Some(z), o);
        assert_eq!(
            keyframe_in::<Pose3>(&k).unwrap().1.guess.map(|g| g.translation),
            Some(z.translation)
        );
        k.guess[4] = f64::NAN;
        assert_eq!(
            keyframe_in::<Pose3>(&k).unwrap_err().reason(),
            RejectionReason::NonFinite
        );
        // an indefinite 6×6 information
        let mut bad = m;
        bad.information[20] = -1.0;
        assert_eq!(
            edge_in::<Pose3>(&bad).unwrap_err().reason(),
            RejectionReason::NotPositiveDefinite
        );
    }
}
