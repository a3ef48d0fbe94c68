//! [`Op`]: one change as the engine received it, and how a rebuild of a
//! [`State`](super::state::State) polishes ([`Polish`]).

use super::pose::EnginePose;
use super::EdgeInput;
use crate::geometry::Pose2;
use crate::gps::GpsFix;
use crate::graph::KeyframeInput;
use slamd_protocol::codec::Origin;

/// One change to the graph, as the engine received it.
#[derive(Clone, Debug)]
pub enum Op<P: EnginePose = Pose2> {
    /// A new keyframe: its id, a guess of its pose in the map frame if
    /// known, its timestamp.
    Keyframe(KeyframeInput<P>),
    /// A new edge, and who sent it.
    Edge(EdgeInput<P>, Origin),
    /// A GPS fix on a known keyframe, in the engine's ENU frame.
    Gps(GpsFix),
    /// A new weight `scale ∈ [0, ∞)` for an edge (0 removes it).
    Weight {
        /// The edge's index.
        edge: usize,
        /// Its new scale.
        scale: f64,
    },
    /// The outlier filter's decision on a loop closure: its switch
    /// `s ∈ [0, 1]` (the judge's, see [`super::judge`]). It is no longer
    /// pending.
    Switch {
        /// The edge's index.
        edge: usize,
        /// Its switch.
        switch: f64,
    },
}

/// How [`rebuild`](super::rebuild::rebuild) moves the
/// linearisation point before it refactorises.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Polish {
    /// The re-solve's: the robust multi-start polish that sets the outlier
    /// filter's switches, then the georeference.
    Full,
    /// [`Polish::Full`] in the foreground, with any background re-solve
    /// stopped (the drift check's): its starts are probed two at a time,
    /// with the outcome of one at a time.
    FullInline,
    /// [`Polish::FullInline`] at the end of a stream, with two more
    /// starts: the two-stage solutions without the loop closures let in on
    /// arrival since the last multi-start re-solve, and without any loop
    /// closure (the dead-reckoned map).
    Closing,
    /// The nonlinearity check's inline re-solve: the robust polish from
    /// the current estimate alone; the next background re-solve has the
    /// two-stage starts (inline they cost a keyframe seconds and, from the
    /// estimate's basin, reach the same optimum). Also the background job
    /// that takes the outlier filter's decisions into the estimate.
    Inline,
    /// None: refactorise at the estimate.
    None,
}
