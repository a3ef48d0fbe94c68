//! [`Snapshot`]: the estimate the engine publishes after each update.

use super::model::KeyframeState;
use crate::geometry::Pose2;
use crate::gps::{Geodetic, Georef};
use crate::graph::{Keyframe, KeyframeId, RigidMotion};

/// A borrowed view of the current estimate: the poses of every keyframe
/// linked to the gauge, with a version number and the χ² of the estimate.
#[derive(Clone, Copy, Debug)]
pub struct Snapshot<'a, P: RigidMotion = Pose2> {
    /// Increases by one with every [`update`](super::Engine::update).
    pub version: u64,
    /// χ² of the estimate over the applied edges, with their weights.
    pub chi2: f64,
    /// Number of completed re-solves so far.
    pub resolves: usize,
    pub(super) keyframes: &'a [Keyframe<P>],
    pub(super) states: &'a [KeyframeState],
    pub(super) poses: &'a [P],
    /// The map→ENU motion, once two GPS fixes have georeferenced the map.
    pub georef: Option<Georef>,
    /// The geodetic origin of the ENU frame, once known.
    pub origin: Option<Geodetic>,
    /// Loop closures held out of the estimate until the outlier filter's
    /// judge decides them.
    pub pending: usize,
}

impl<'a, P: RigidMotion> Snapshot<'a, P> {
    /// `(id, pose)` of every keyframe in the estimate, in arrival order.
    pub fn poses(&self) -> impl Iterator<Item = (KeyframeId, P)> + 'a {
        let (k, s, p) = (self.keyframes, self.states, self.poses);
        (0..k.len())
            .filter(move |&i| s[i].joined)
            .map(move |i| (k[i].id, p[i]))
    }

    /// The timestamp (ns; 0: none) of each keyframe [`Self::poses`] yields,
    /// in the same order.
    pub fn timestamps(&self) -> impl Iterator<Item = u64> + 'a {
        (self.states.iter()).filter(|s| s.joined).map(|s| s.timestamp_ns)
    }

    /// The newest keyframe in the estimate.
    pub fn newest(&self) -> Option<KeyframeId> {
        (0..self.states.len())
            .rev()
            .find(|&i| self.states[i].joined)
            .map(|i| self.keyframes[i].id)
    }

    /// `(id, pose, timestamp ns)` of the keyframe at `index` (arrival
    /// order), if it is in the estimate.
    pub fn entry(&self, index: usize) -> Option<(KeyframeId, P, u64)> {
        let s = self.states.get(index).filter(|s| s.joined)?;
        Some((self.keyframes[index].id, self.poses[index], s.timestamp_ns))
    }

    /// Keyframes received, joined to the map or not: the indices
    /// [`Self::entry`] and [`Self::pose`] take run below it.
    pub fn keyframes(&self) -> usize {
        self.keyframes.len()
    }

    /// The pose of one keyframe, if it is in the estimate.
    pub fn pose(&self, index: usize) -> Option<P> {
        (self.states.get(index).is_some_and(|s| s.joined)).then(|| self.poses[index])
    }

    /// Number of keyframes in the estimate.
    pub fn len(&self) -> usize {
        self.states.iter().filter(|s| s.joined).count()
    }

    /// True when no keyframe is in the estimate.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl<'a> Snapshot<'a> {
    /// The pose of one keyframe in ENU (x east, y north, heading from
    /// east), when the map is georeferenced.
    pub fn enu_pose(&self, index: usize) -> Option<Pose2> {
        Some(self.georef?.to_enu(&self.pose(index)?))
    }

    /// `(id, ENU pose)` of every keyframe in the estimate; empty until the
    /// map is georeferenced.
    pub fn enu_poses(&self) -> impl Iterator<Item = (KeyframeId, Pose2)> + 'a {
        let g = self.georef;
        self.poses()
            .filter_map(move |(id, p)| g.map(|g| (id, g.to_enu(&p))))
    }
}
