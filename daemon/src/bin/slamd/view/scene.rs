//! What the live view shows, built from the daemon's output alone: pure
//! functions from a snapshot and the loop closures' switches to Foxglove's
//! well-known messages and to the page's JSON.
//!
//! Odometry is drawn as the chain of keyframes in the order the snapshot
//! lists them (the order they arrived), since snapshots carry no odometry
//! edges; every loop closure is drawn from its switch, in the colour of
//! its state.

use foxglove::messages::{
    line_primitive, Color, LocationFix, LocationFixes, Point3, Pose as FoxPose, PoseInFrame, PosesInFrame,
    Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
};
use nalgebra::{Matrix2, Matrix3, Rotation3, SymmetricEigen, UnitQuaternion};
use slamd::gps::{Geodetic, LocalFrame};
use slamd_protocol::{DaemonStatus, Pose, SnapshotHeader, Switch, SwitchState};
use std::collections::HashMap;

/// The frame every pose is given in.
pub const MAP_FRAME: &str = "map";

/// How many standard deviations the newest keyframe's ellipsoid spans on
/// each side (3σ: 99% of a planar Gaussian lies within 3.03σ).
pub const SIGMAS: f64 = 3.0;

/// The newest snapshot and loop-closure switches the viewer has read.
#[derive(Clone, Debug, Default)]
pub struct Frame {
    /// The snapshot's header.
    pub header: SnapshotHeader,
    /// Its poses, in the snapshot's order.
    pub poses: Vec<Pose>,
    /// One switch per loop closure, in arrival order.
    pub loops: Vec<Switch>,
}

/// A loop closure's colour in both views, by what the filter holds of it.
fn color(state: SwitchState) -> Color {
    match state {
        SwitchState::Kept => rgb(0.16, 0.63, 0.30),
        SwitchState::Off => rgb(0.86, 0.15, 0.15),
        SwitchState::Pending => rgb(0.96, 0.62, 0.07),
    }
}

fn rgb(r: f64, g: f64, b: f64) -> Color {
    Color { r, g, b, a: 1.0 }
}

/// The message timestamp of nanoseconds since the UNIX epoch.
pub fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new(
        (ns / 1_000_000_000).min(u64::from(u32::MAX)) as u32,
        (ns % 1_000_000_000) as u32,
    )
}

fn position(p: &Pose) -> Vector3 {
    Vector3 {
        x: p.x,
        y: p.y,
        z: p.z,
    }
}

fn point(p: &Pose) -> Point3 {
    Point3 {
        x: p.x,
        y: p.y,
        z: p.z,
    }
}

fn fox_pose(p: &Pose) -> FoxPose {
    FoxPose {
        position: Some(position(p)),
        orientation: Some(Quaternion {
            x: p.qx,
            y: p.qy,
            z: p.qz,
            w: p.qw,
        }),
    }
}

impl Frame {
    fn stamp(&self) -> Option<Timestamp> {
        Some(timestamp(self.header.solved_at_ns))
    }

    /// The index of each keyframe id in `poses`.
    fn index(&self) -> HashMap<u64, usize> {
        (self.poses.iter().enumerate()).map(|(i, p)| (p.id, i)).collect()
    }

    /// The loop closures whose both keyframes are in the snapshot, with
    /// their state: `(from index, to index, state)`; what
    /// [`Self::graph`] and [`Self::page_map`] draw.
    pub fn loop_closures(&self) -> Vec<(usize, usize, SwitchState)> {
        let index = self.index();
        (self.loops.iter())
            .filter_map(|s| Some((*index.get(&s.from)?, *index.get(&s.to)?, s.state())))
            .collect()
    }

    /// The newest keyframe: the one whose covariance the header carries,
    /// else the last pose.
    pub fn newest(&self) -> Option<&Pose> {
        if self.header.has_covariance != 0 {
            let id = self.header.covariance_keyframe;
            if let Some(p) = self.poses.iter().rev().find(|p| p.id == id) {
                return Some(p);
            }
        }
        self.poses.last()
    }

    /// The trajectory: every pose of the snapshot in the map frame.
    pub fn trajectory(&self) -> PosesInFrame {
        PosesInFrame {
            timestamp: self.stamp(),
            frame_id: MAP_FRAME.into(),
            poses: self.poses.iter().map(fox_pose).collect(),
        }
    }

    /// The newest keyframe's pose.
    pub fn newest_pose(&self) -> Option<PoseInFrame> {
        Some(PoseInFrame {
            timestamp: self.stamp(),
            frame_id: MAP_FRAME.into(),
            pose: Some(fox_pose(self.newest()?)),
        })
    }

    /// The graph: entity `graph` with one line primitive for the odometry
    /// chain and one per loop-closure state (its metadata counts each),
    /// and entity `newest` with the newest keyframe's position ellipsoid
    /// at [`SIGMAS`] when the header carries its covariance. `loops` is
    /// [`Self::loop_closures`].
    pub fn graph(&self, loops: &[(usize, usize, SwitchState)]) -> SceneUpdate {
        let odometry = line(
            LineType::LineStrip,
            rgb(0.55, 0.55, 0.55),
            self.poses.iter().map(point),
        );
        let mut lines = vec![odometry];
        let mut metadata = Vec::new();
        for state in SwitchState::ALL {
            let ends = (loops.iter().filter(|l| l.2 == state))
                .flat_map(|&(i, j, _)| [point(&self.poses[i]), point(&self.poses[j])]);
            let l = line(LineType::LineList, color(state), ends);
            metadata.push(foxglove::messages::KeyValuePair {
                key: state.name().into(),
                value: (l.points.len() / 2).to_string(),
            });
            lines.push(l);
        }
        let mut entities = vec![SceneEntity {
            timestamp: self.stamp(),
            frame_id: MAP_FRAME.into(),
            id: "graph".into(),
            metadata,
            lines,
            ..Default::default()
        }];
        if let Some(sphere) = self.newest().and_then(|p| ellipsoid(&self.header, p)) {
            entities.push(SceneEntity {
                timestamp: self.stamp(),
                frame_id: MAP_FRAME.into(),
                id: "newest".into(),
                spheres: vec![sphere],
                ..Default::default()
            });
        }
        SceneUpdate {
            deletions: Vec::new(),
            entities,
        }
    }

    /// The georeferenced trajectory, once GPS has georeferenced the map:
    /// every keyframe as a WGS84 fix, and the newest alone.
    pub fn locations(&self) -> Option<(LocationFixes, LocationFix)> {
        let h = &self.header;
        if h.georeferenced == 0 || h.has_origin == 0 {
            return None;
        }
        let frame = LocalFrame::new(Geodetic {
            lat: h.origin[0],
            lon: h.origin[1],
            height: h.origin[2],
        });
        let fix = |p: &Pose| {
            let g = frame.to_geodetic(p.east, p.north, p.up);
            LocationFix {
                timestamp: Some(timestamp(if p.timestamp_ns != 0 {
                    p.timestamp_ns
                } else {
                    h.solved_at_ns
                })),
                frame_id: MAP_FRAME.into(),
                latitude: g.lat,
                longitude: g.lon,
                altitude: g.height,
                ..Default::default()
            }
        };
        let newest = fix(self.newest()?);
        Some((
            LocationFixes {
                fixes: self.poses.iter().map(fix).collect(),
            },
            newest,
        ))
    }

    /// The page's map: `{"version", "dimension", "poses": [[id, x, y], …],
    /// "loops": [[from id, to id, state], …]}` (the page draws from above).
    /// `loops` is [`Self::loop_closures`].
    pub fn page_map(&self, loops: &[(usize, usize, SwitchState)]) -> Vec<u8> {
        #[derive(serde::Serialize)]
        struct PageMap {
            version: u64,
            dimension: u32,
            poses: Vec<(u64, f64, f64)>,
            loops: Vec<(u64, u64, &'static str)>,
        }
        let map = PageMap {
            version: self.header.version,
            dimension: self.header.dimension,
            poses: self.poses.iter().map(|p| (p.id, p.x, p.y)).collect(),
            loops: (loops.iter())
                .map(|&(i, j, s)| (self.poses[i].id, self.poses[j].id, s.name()))
                .collect(),
        };
        serde_json::to_vec(&map).unwrap_or_default()
    }
}

/// Shorthand for the line primitive's type.
type LineType = line_primitive::Type;

fn line(
    kind: LineType,
    color: Color,
    points: impl Iterator<Item = Point3>,
) -> foxglove::messages::LinePrimitive {
    foxglove::messages::LinePrimitive {
        r#type: kind as i32,
        pose: None,
        thickness: 1.5,
        scale_invariant: true,
        points: points.collect(),
        color: Some(color),
        ..Default::default()
    }
}

/// The daemon's health for plots: its counters, χ², latency and journal.
pub fn health(h: &SnapshotHeader, status: Option<&DaemonStatus>) -> serde_json::Value {
    let mut v = serde_json::json!({
        "version": h.version,
        "keyframes": h.keyframes,
        "edges": h.edges,
        "rejected": h.rejected,
        "pending": h.pending,
        "held": h.held,
        "resolves": h.resolves,
        "fixes": h.fixes,
        "chi2": h.chi2,
        "georeferenced": h.georeferenced != 0,
    });
    if let Some(s) = status {
        v["latency_p50_us"] = s.latency_p50_us.into();
        v["latency_p99_us"] = s.latency_p99_us.into();
        v["frontends"] = s.frontends.into();
        v["journal_failing"] = (s.journal_failing != 0).into();
        v["journal_bytes"] = s.journal_bytes.into();
    }
    v
}

/// The ellipsoid of the newest keyframe's position covariance, in the map
/// frame: axes along the eigenvectors of `R Σ_t Rᵀ` (Σ_t the position
/// block of the covariance in the pose's own frame, R its rotation), each
/// `2 · SIGMAS · √λ` long. A planar ellipse is drawn as a flat ellipsoid.
pub fn ellipsoid(h: &SnapshotHeader, p: &Pose) -> Option<SpherePrimitive> {
    if h.has_covariance == 0 || h.covariance_keyframe != p.id {
        return None;
    }
    let c = &h.covariance;
    // the upper triangle row by row: (x, y, θ) in the plane, (x, y, z, r…)
    // in space
    let block = if h.dimension == 3 {
        Matrix3::new(c[0], c[1], c[2], c[1], c[6], c[7], c[2], c[7], c[11])
    } else {
        let m = Matrix2::new(c[0], c[1], c[1], c[3]);
        let mut b = Matrix3::zeros();
        b.fixed_view_mut::<2, 2>(0, 0).copy_from(&m);
        b
    };
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(p.qw, p.qx, p.qy, p.qz));
    let r = q.to_rotation_matrix();
    let map = r.matrix() * block * r.matrix().transpose();
    if !map.iter().all(|v| v.is_finite()) {
        return None;
    }
    let eig = SymmetricEigen::new(map);
    let mut axes = eig.eigenvectors;
    if axes.determinant() < 0.0 {
        axes.column_mut(2).neg_mut();
    }
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
    let len = eig.eigenvalues.map(|l| 2.0 * SIGMAS * l.max(0.0).sqrt());
    let flat = 1e-3 * len.max().max(1e-6);
    let size = len.map(|l| l.max(flat));
    Some(SpherePrimitive {
        pose: Some(FoxPose {
            position: Some(position(p)),
            orientation: Some(Quaternion {
                x: rot.i,
                y: rot.j,
                z: rot.k,
                w: rot.w,
            }),
        }),
        size: Some(Vector3 {
            x: size[0],
            y: size[1],
            z: size[2],
        }),
        color: Some(Color {
            r: 0.2,
            g: 0.45,
            b: 0.9,
            a: 0.35,
        }),
    })
}

#[cfg(test)]
mod tests;
