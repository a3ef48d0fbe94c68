//! [`Edge`]: one relative-pose measurement between two keyframes.

use super::{EdgeKind, RigidMotion};
use crate::geometry::Pose2;

/// A measurement `T_ij` of keyframe `j` seen from keyframe `i`, with its
/// information matrix Ω_ij. `from` and `to` are indices into a
/// [`PoseGraph`](super::PoseGraph).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge<P: RigidMotion = Pose2> {
    /// Index of keyframe `i`.
    pub from: usize,
    /// Index of keyframe `j`.
    pub to: usize,
    /// `T_ij`, the pose of `j` in the frame of `i`.
    pub measurement: P,
    /// Ω_ij over the error of `T_ij⁻¹ T_i⁻¹ T_j` (`t2v` in the plane,
    /// `[Δt, Δq_xyz]` in space).
    pub information: P::Information,
    /// What produced it.
    pub kind: EdgeKind,
}

impl Edge {
    /// A loop closure `z` from keyframe index `from` to `to` with unit
    /// information (tests' shorthand).
    #[cfg(test)]
    pub(crate) fn unit_loop_closure(from: usize, to: usize, z: Pose2) -> Edge {
        Edge {
            from,
            to,
            measurement: z,
            information: super::Information::identity(),
            kind: EdgeKind::LoopClosure,
        }
    }
}

impl<P: RigidMotion> Edge<P> {
    /// The newer keyframe index, `max(i, j)`: when the edge becomes available
    /// to an online solver.
    pub fn newer(&self) -> usize {
        self.from.max(self.to)
    }

    /// The older keyframe index, `min(i, j)`.
    pub fn older(&self) -> usize {
        self.from.min(self.to)
    }
}
