//! [`MapFile`]: a whole map as one versioned file, the daemon's checkpoint
//! and what `slamd run --map` continues from.
//!
//! File: a 24-byte head `"SLAMDMAP" | version: u32 | crc32c: u32 |
//! generation: u64` (the checksum covers the other three fields), then one
//! frame (`len: u32 | crc32c: u32 | body`) whose body is, in
//! order (counts are `u64`, everything little-endian):
//!
//! - the dimension: `u8`, 2 or 3 (not in version 1 files, which are 2-D);
//! - keyframes: `id: u64, joined: u8, has_guess: u8, guess, estimate,
//!   linearisation point`, each pose as `x, y, θ` (2-D) or `x, y, z, qx,
//!   qy, qz, qw` (3-D) in `f64`s, in arrival order (the first is the
//!   gauge);
//! - edges: the edge as a journal record holds it, then `scale, switch:
//!   f64, frontend: u32, sequence: u64`;
//! - the GPS origin: `has: u8, lat, lon, height: f64`;
//! - the georeference: `has: u8, rotation: 2 × f64, translation: 2 × f64,
//!   weight: f64`;
//! - fixes: as a journal record's body;
//! - acknowledgements: `frontend: u32, through: u64`, then the count and
//!   the numbers taken beyond `through`;
//! - held messages (edges and fixes waiting for their keyframe): each a
//!   `u32` length and a journal record's payload;
//! - (not in version 1) the georeference's up offset (`f64`, 0 without
//!   one) and each fix's height variance (`f64`, 0: the height is free);
//! - (version 3 on) each keyframe's timestamp (`u64` ns, 0: none).

use super::bytes::{frame, unframe, Framed, Get, Put};
use super::journal::{check_head, head, HEAD};
use super::record::{edge_of_version, get_edge, get_fix, get_pose, put_edge, put_fix, put_pose, Record};
use super::StoreError;
use crate::gps::Georef;
use crate::graph::{GraphError, PoseGraph};
use faer::c64;
use slamd_protocol::codec::Origin;
use slamd_types::{EdgeInput, FixInput, Geodetic, InformationMatrix, KeyframeId, Pose2, RigidMotion};
use std::path::Path;

/// The map file's first bytes.
pub const MAGIC: &[u8; 8] = b"SLAMDMAP";

/// A keyframe of a saved map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapKeyframe<P: RigidMotion = Pose2> {
    /// Its id.
    pub id: KeyframeId,
    /// The frontend's guess, if it gave one.
    pub guess: Option<P>,
    /// The estimate when the map was saved.
    pub estimate: P,
    /// Where the engine had linearised it (the estimate is one
    /// Gauss–Newton step from there): a restored engine factorises here
    /// and publishes the same estimate.
    pub lin: P,
    /// Whether it was linked to the gauge.
    pub joined: bool,
    /// When the frontend took it (ns; 0: it gave no time).
    pub timestamp_ns: u64,
}

/// An edge of a saved map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapEdge<P: RigidMotion = Pose2> {
    /// The edge as received.
    pub edge: EdgeInput<P>,
    /// Its weight as set through the engine.
    pub scale: f64,
    /// The outlier filter's switch.
    pub switch: f64,
    /// A loop closure the filter had not decided: held out (switch 0)
    /// until it does.
    pub pending: bool,
    /// Who sent it.
    pub origin: Origin,
}

/// One frontend's acknowledgement: every number through `through` was
/// taken, and so were those in `beyond`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AckState {
    /// The frontend.
    pub frontend: u32,
    /// Every message numbered up to this one was taken.
    pub through: u64,
    /// Messages taken past a gap.
    pub beyond: Vec<u64>,
}

/// The map→ENU georeference and the weight of the GPS priors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SavedGeoref {
    /// The motion.
    pub georef: Georef,
    /// The weight every GPS prior carries.
    pub weight: f64,
}

/// A whole map; `P` is its pose type.
#[derive(Clone, Debug, PartialEq)]
pub struct MapFile<P: RigidMotion = Pose2> {
    /// Bumped by each checkpoint; the journal names the one it follows.
    pub generation: u64,
    /// Keyframes in arrival order.
    pub keyframes: Vec<MapKeyframe<P>>,
    /// Edges in arrival order.
    pub edges: Vec<MapEdge<P>>,
    /// The ENU origin of the GPS fixes.
    pub origin: Option<Geodetic>,
    /// The georeference of the last re-solve.
    pub georef: Option<SavedGeoref>,
    /// GPS fixes in arrival order.
    pub fixes: Vec<FixInput>,
    /// What each frontend has had acknowledged.
    pub acks: Vec<AckState>,
    /// Edges and fixes waiting for a keyframe.
    pub held: Vec<Record<P>>,
}

impl<P: RigidMotion> Default for MapFile<P> {
    fn default() -> Self {
        Self {
            generation: 0,
            keyframes: Vec::new(),
            edges: Vec::new(),
            origin: None,
            georef: None,
            fixes: Vec::new(),
            acks: Vec::new(),
            held: Vec::new(),
        }
    }
}

impl<P: RigidMotion> MapFile<P> {
    /// The map of `graph` solved at `poses` (one per keyframe, in order):
    /// every keyframe joined and linearised at its pose, every edge at
    /// weight 1 and switched on. [`Engine::restore`](crate::engine::Engine::restore)
    /// of it factorises the graph at `poses` (for their covariances).
    pub fn solved(graph: &PoseGraph<P>, poses: &[P]) -> Self {
        let keyframes = graph
            .keyframes()
            .iter()
            .zip(poses)
            .map(|(k, &pose)| MapKeyframe {
                id: k.id,
                guess: k.guess,
                estimate: pose,
                lin: pose,
                joined: true,
                timestamp_ns: 0,
            })
            .collect();
        let edges = (0..graph.edges().len())
            .map(|e| MapEdge {
                edge: graph.edge_input(e),
                scale: 1.0,
                switch: 1.0,
                pending: false,
                origin: Origin {
                    frontend: 0,
                    sequence: 0,
                },
            })
            .collect();
        Self {
            keyframes,
            edges,
            ..Self::default()
        }
    }

    /// The file's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut p = Put::default();
        p.u8(P::DIMENSION as u8);
        p.u64(self.keyframes.len() as u64);
        for k in &self.keyframes {
            p.u64(k.id);
            p.u8(u8::from(k.joined));
            p.u8(u8::from(k.guess.is_some()));
            put_pose(&mut p, &k.guess.unwrap_or(P::IDENTITY));
            put_pose(&mut p, &k.estimate);
            put_pose(&mut p, &k.lin);
        }
        p.u64(self.edges.len() as u64);
        for e in &self.edges {
            put_edge(&mut p, &e.edge);
            p.f64(e.scale);
            p.f64(if e.pending { PENDING_SWITCH } else { e.switch });
            p.u32(e.origin.frontend);
            p.u64(e.origin.sequence);
        }
        p.u8(u8::from(self.origin.is_some()));
        let o = self.origin.unwrap_or(Geodetic {
            lat: 0.0,
            lon: 0.0,
            height: 0.0,
        });
        p.f64s(&[o.lat, o.lon, o.height]);
        p.u8(u8::from(self.georef.is_some()));
        let g = self.georef.map_or([0.0; 5], |s| {
            let (r, t) = (s.georef.rotation, s.georef.translation);
            [r.re, r.im, t.re, t.im, s.weight]
        });
        p.f64s(&g);
        p.u64(self.fixes.len() as u64);
        for f in &self.fixes {
            put_fix(&mut p, f);
        }
        p.u64(self.acks.len() as u64);
        for a in &self.acks {
            p.u32(a.frontend);
            p.u64(a.through);
            p.u64(a.beyond.len() as u64);
            for &s in &a.beyond {
                p.u64(s);
            }
        }
        p.u64(self.held.len() as u64);
        for r in &self.held {
            let mut q = Put::default();
            r.encode(&mut q);
            p.u32(q.0.len() as u32);
            p.0.extend_from_slice(&q.0);
        }
        p.f64(self.georef.map_or(0.0, |g| g.georef.up));
        for f in &self.fixes {
            p.f64(f.height_variance.unwrap_or(0.0));
        }
        for k in &self.keyframes {
            p.u64(k.timestamp_ns);
        }
        let mut out = head(MAGIC, self.generation);
        out.reserve(8 + p.0.len());
        frame(&mut out, &p.0);
        out
    }

    /// Reads a map file's bytes; `path` labels errors.
    pub fn decode(path: &Path, bytes: &[u8]) -> Result<MapFile<P>, StoreError> {
        let (generation, version) = check_head(path, bytes, MAGIC, "map")?;
        let body = match unframe(&bytes[HEAD..]) {
            Framed::Whole(body, used) if HEAD + used == bytes.len() => body,
            Framed::Whole(..) => return Err(corrupt(path, "bytes after the map")),
            Framed::Torn => return Err(corrupt(path, "the file ends early")),
            Framed::Corrupt => return Err(corrupt(path, "checksum mismatch")),
        };
        decode_body(body, generation, version).map_err(|e| match e {
            StoreError::Dimension { .. } => e,
            e => corrupt(path, &e.to_string()),
        })
    }

    /// Reads a map file.
    pub fn read(path: &Path) -> Result<MapFile<P>, StoreError> {
        let bytes = std::fs::read(path).map_err(|e| StoreError::io("read", path, e))?;
        Self::decode(path, &bytes)
    }

    /// The map as a pose graph: each keyframe with its saved estimate as
    /// its guess (where it had joined), every edge as received.
    pub fn graph(&self) -> Result<PoseGraph<P>, GraphError> {
        let mut g = PoseGraph::default();
        for k in &self.keyframes {
            g.add_keyframe(k.id, if k.joined { Some(k.estimate) } else { k.guess })?;
        }
        for e in &self.edges {
            let i = &e.edge;
            g.add_edge(i.from, i.to, i.measurement, i.information, i.kind)?;
        }
        Ok(g)
    }
}

impl MapFile {
    /// Whether `bytes` start like a map file.
    pub fn sniff(bytes: &[u8]) -> bool {
        bytes.starts_with(MAGIC)
    }
}

/// The switch a map (format 5 on) writes for a pending loop closure.
const PENDING_SWITCH: f64 = -1.0;

fn corrupt(path: &Path, why: &str) -> StoreError {
    StoreError::Corrupt {
        path: path.to_path_buf(),
        why: why.into(),
    }
}

fn decode_body<P: RigidMotion>(body: &[u8], generation: u64, version: u32) -> Result<MapFile<P>, StoreError> {
    let mut g = Get::new(body);
    let dimension = if version == 1 { 2 } else { u32::from(g.u8()?) };
    if dimension != P::DIMENSION {
        return Err(StoreError::Dimension {
            found: dimension,
            serving: P::DIMENSION,
        });
    }
    let mut map = MapFile {
        generation,
        ..MapFile::default()
    };
    let pose_bytes = 8 * P::PARAMS;
    for _ in 0..g.count(10 + 3 * pose_bytes)? {
        let id = g.u64()?;
        let joined = g.u8()? != 0;
        let has_guess = g.u8()? != 0;
        let guess = get_pose(&mut g)?;
        let estimate = get_pose(&mut g)?;
        let lin = get_pose(&mut g)?;
        map.keyframes.push(MapKeyframe {
            id,
            guess: has_guess.then_some(guess),
            estimate,
            lin,
            joined,
            timestamp_ns: 0,
        });
    }
    for _ in 0..g.count(17 + pose_bytes + 8 * P::Information::UPPER + 28)? {
        let edge = edge_of_version(get_edge(&mut g)?, version);
        let scale = g.f64()?;
        let switch = g.f64()?;
        let pending = version >= 5 && switch == PENDING_SWITCH;
        let switch = if pending { 0.0 } else { switch };
        if !(scale.is_finite() && scale >= 0.0 && (0.0..=1.0).contains(&switch)) {
            return Err(StoreError::Malformed(format!(
                "edge {}→{}: scale {scale}, switch {switch}",
                edge.from, edge.to
            )));
        }
        let origin = Origin {
            frontend: g.u32()?,
            sequence: g.u64()?,
        };
        map.edges.push(MapEdge {
            edge,
            scale,
            switch,
            pending,
            origin,
        });
    }
    let has_origin = g.u8()? != 0;
    let [lat, lon, height] = g.f64s()?;
    if has_origin {
        map.origin = Some(Geodetic::new(lat, lon, height).map_err(|e| StoreError::Malformed(e.to_string()))?);
    }
    let has_georef = g.u8()? != 0;
    let [rr, ri, tr, ti, weight] = g.f64s()?;
    if has_georef {
        if ![rr, ri, tr, ti, weight].iter().all(|v| v.is_finite()) {
            return Err(StoreError::Malformed("georeference not finite".into()));
        }
        map.georef = Some(SavedGeoref {
            georef: Georef {
                rotation: c64::new(rr, ri),
                translation: c64::new(tr, ti),
                up: 0.0,
            },
            weight,
        });
    }
    for _ in 0..g.count(64)? {
        map.fixes.push(get_fix(&mut g, false)?);
    }
    for _ in 0..g.count(20)? {
        let frontend = g.u32()?;
        let through = g.u64()?;
        let n = g.count(8)?;
        let beyond = (0..n).map(|_| g.u64()).collect::<Result<_, _>>()?;
        map.acks.push(AckState {
            frontend,
            through,
            beyond,
        });
    }
    for _ in 0..g.count(4)? {
        let len = g.u32()? as usize;
        let mut bytes = Vec::with_capacity(len.min(256));
        for _ in 0..len {
            bytes.push(g.u8()?);
        }
        map.held.push(Record::decode(&bytes)?.of_version(version));
    }
    if version >= 2 {
        let up = g.f64()?;
        if let Some(s) = &mut map.georef {
            s.georef.up = up;
        }
        for f in &mut map.fixes {
            let v = g.f64()?;
            f.height_variance = (v != 0.0).then_some(v);
            if f.check().is_err() {
                return Err(StoreError::Malformed(format!(
                    "fix on keyframe {}: bad height variance {v}",
                    f.keyframe
                )));
            }
        }
    }
    if version >= 3 {
        for k in &mut map.keyframes {
            k.timestamp_ns = g.u64()?;
        }
    }
    g.finish()?;
    Ok(map)
}
