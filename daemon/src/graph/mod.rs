//! The pose graph: keyframes (the variables) and edges (the factors).
//!
//! Keyframes carry the frontend's id ([`KeyframeId`]) and are stored in id
//! order, so index 0 is the keyframe with the smallest id: the gauge, fixed at
//! the origin by every solver.

mod cost;
mod cost3;
mod edge;

pub use cost::{chi2, chi2_of_edges, edge_chi2, edge_error, edge_error_turned, EdgeCost};
pub(crate) use cost3::Delta3;
pub use edge::Edge;
use slamd_types::EdgeInput;
pub use slamd_types::{
    EdgeKind, Information, Information6, InformationError, KeyframeId, KeyframeInput, Pose3,
};

use crate::geometry::Pose2;
pub use slamd_types::{InformationMatrix, RigidMotion};
use std::collections::{HashMap, VecDeque};
use std::fmt;

/// Why a keyframe or an edge cannot join a graph.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum GraphError {
    /// A keyframe with this id already exists.
    DuplicateKeyframe(KeyframeId),
    /// An edge names a keyframe that does not exist.
    UnknownKeyframe(KeyframeId),
    /// An edge from a keyframe to itself.
    SelfEdge(KeyframeId),
    /// A measurement or initial guess with NaN or infinity.
    NonFinite(&'static str),
    /// A bad information matrix.
    Information(InformationError),
    /// Some keyframe is not linked to the gauge keyframe by any chain of edges.
    NotConnected {
        /// The first keyframe found unreachable.
        unreachable: KeyframeId,
        /// The gauge keyframe.
        gauge: KeyframeId,
    },
    /// The graph has no keyframes.
    Empty,
}

impl fmt::Display for GraphError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GraphError::DuplicateKeyframe(id) => write!(f, "duplicate keyframe id {id}"),
            GraphError::UnknownKeyframe(id) => write!(f, "edge refers to unknown keyframe {id}"),
            GraphError::SelfEdge(id) => write!(f, "edge from keyframe {id} to itself"),
            GraphError::NonFinite(what) => write!(f, "non-finite value in {what}"),
            GraphError::Information(e) => e.fmt(f),
            GraphError::NotConnected { unreachable, gauge } => write!(
                f,
                "graph is not connected: keyframe {unreachable} has no chain of edges to keyframe {gauge}"
            ),
            GraphError::Empty => f.write_str("graph has no keyframes"),
        }
    }
}

impl std::error::Error for GraphError {}

impl From<InformationError> for GraphError {
    fn from(e: InformationError) -> Self {
        GraphError::Information(e)
    }
}

/// A keyframe: its id and, if the source gave one, an initial guess.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keyframe<P: RigidMotion = Pose2> {
    /// The frontend's id.
    pub id: KeyframeId,
    /// The initial pose from the source (a `VERTEX` line), if any.
    pub guess: Option<P>,
}

/// Keyframes plus edges, with a map from ids to indices.
///
/// `P` is the pose type: [`Pose2`] for planar graphs (the default),
/// [`Pose3`] for spatial ones.
#[derive(Clone, Debug, Default)]
pub struct PoseGraph<P: RigidMotion = Pose2> {
    keyframes: Vec<Keyframe<P>>,
    index: HashMap<KeyframeId, usize>,
    edges: Vec<Edge<P>>,
}

impl<P: RigidMotion> PoseGraph<P> {
    /// Edge `e` as a frontend sends it (keyframe ids, not indices).
    pub fn edge_input(&self, e: usize) -> EdgeInput<P> {
        let edge = self.edges[e];
        EdgeInput::new(
            self.id_of(edge.from),
            self.id_of(edge.to),
            edge.measurement,
            edge.information,
            edge.kind,
        )
    }
}

impl<P: RigidMotion> PoseGraph<P> {
    /// Builds a graph whose keyframes are `keyframes` sorted by id.
    pub fn with_keyframes(mut keyframes: Vec<Keyframe<P>>) -> Result<Self, GraphError> {
        keyframes.sort_by_key(|k| k.id);
        let mut graph = Self::default();
        for k in keyframes {
            graph.add_keyframe(k.id, k.guess)?;
        }
        Ok(graph)
    }

    /// A graph from keyframes (in index order, ids distinct) and edges that
    /// already refer to keyframe indices.
    pub fn from_parts(keyframes: Vec<Keyframe<P>>, edges: Vec<Edge<P>>) -> Result<Self, GraphError> {
        let mut graph = Self::default();
        for k in keyframes {
            graph.add_keyframe(k.id, k.guess)?;
        }
        for e in &edges {
            if e.from >= graph.len() || e.to >= graph.len() {
                return Err(GraphError::UnknownKeyframe(e.from.max(e.to) as KeyframeId));
            }
        }
        graph.edges = edges;
        Ok(graph)
    }

    /// Appends a keyframe and returns its index. Ids need not be sorted here,
    /// but index 0 (the gauge) is whichever keyframe comes first.
    pub fn add_keyframe(&mut self, id: KeyframeId, guess: Option<P>) -> Result<usize, GraphError> {
        if self.index.contains_key(&id) {
            return Err(GraphError::DuplicateKeyframe(id));
        }
        if guess.is_some_and(|g| !g.is_finite()) {
            return Err(GraphError::NonFinite("keyframe guess"));
        }
        let idx = self.keyframes.len();
        self.keyframes.push(Keyframe { id, guess });
        self.index.insert(id, idx);
        Ok(idx)
    }

    /// Appends an edge between two existing keyframes and returns its index.
    ///
    /// The edge is kept as written, whichever keyframe is newer: its error
    /// is `t2v(T_ij⁻¹ T_i⁻¹ T_j)` with Ω in that error's frame, as g2o and
    /// GTSAM read it. Writing it the other way, `(j, i, T_ij⁻¹)`, changes
    /// the error to `−Ad(T_ij) e` to first order, so the same Ω there would
    /// be another noise model (docs/design.md, "Edge direction").
    pub fn add_edge(
        &mut self,
        from: KeyframeId,
        to: KeyframeId,
        measurement: P,
        information: P::Information,
        kind: EdgeKind,
    ) -> Result<usize, GraphError> {
        if from == to {
            return Err(GraphError::SelfEdge(from));
        }
        if !measurement.is_finite() {
            return Err(GraphError::NonFinite("edge measurement"));
        }
        let i = self.index_of(from).ok_or(GraphError::UnknownKeyframe(from))?;
        let j = self.index_of(to).ok_or(GraphError::UnknownKeyframe(to))?;
        self.edges.push(Edge {
            from: i,
            to: j,
            measurement,
            information,
            kind,
        });
        Ok(self.edges.len() - 1)
    }

    /// Number of keyframes.
    pub fn len(&self) -> usize {
        self.keyframes.len()
    }

    /// True when there are no keyframes.
    pub fn is_empty(&self) -> bool {
        self.keyframes.is_empty()
    }

    /// The keyframes, by index.
    pub fn keyframes(&self) -> &[Keyframe<P>] {
        &self.keyframes
    }

    /// The edges, in insertion (file) order.
    pub fn edges(&self) -> &[Edge<P>] {
        &self.edges
    }

    /// Mutable access to the edges (reweighting); the topology stays.
    pub fn edges_mut(&mut self) -> &mut [Edge<P>] {
        &mut self.edges
    }

    /// The index of a keyframe id.
    pub fn index_of(&self, id: KeyframeId) -> Option<usize> {
        self.index.get(&id).copied()
    }

    /// The id of the keyframe at `index`.
    pub fn id_of(&self, index: usize) -> KeyframeId {
        self.keyframes[index].id
    }

    /// Edge indices in time order: by `max(i, j)`, then `min(i, j)`, ties in
    /// file order. Streaming edges in this order is what a robot would do.
    pub fn time_order(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.edges.len()).collect();
        order.sort_by_key(|&e| (self.edges[e].newer(), self.edges[e].older()));
        order
    }

    /// Edge indices grouped by their newer keyframe, each group in time
    /// order: what a frontend publishes with each keyframe.
    pub fn by_newer(&self) -> Vec<Vec<usize>> {
        let mut groups = vec![Vec::new(); self.len()];
        for e in self.time_order() {
            groups[self.edges[e].newer()].push(e);
        }
        groups
    }

    /// A copy with the edges permuted into `order`.
    pub fn reordered(&self, order: &[usize]) -> Self {
        Self {
            keyframes: self.keyframes.clone(),
            index: self.index.clone(),
            edges: order.iter().map(|&e| self.edges[e]).collect(),
        }
    }

    /// The sub-graph of keyframes `0..n` and the edges among them, keeping
    /// edge order. Used to check online results against batch prefixes.
    pub fn prefix(&self, n: usize) -> Self {
        let keyframes = self.keyframes[..n].to_vec();
        let index = keyframes.iter().enumerate().map(|(i, k)| (k.id, i)).collect();
        let edges = self.edges.iter().filter(|e| e.newer() < n).copied().collect();
        Self {
            keyframes,
            index,
            edges,
        }
    }

    /// Keyframes adjacent to each keyframe, with the edge index.
    pub fn adjacency(&self) -> Vec<Vec<(usize, usize)>> {
        let mut adj = vec![Vec::new(); self.len()];
        for (k, e) in self.edges.iter().enumerate() {
            adj[e.from].push((e.to, k));
            adj[e.to].push((e.from, k));
        }
        adj
    }

    /// Checks that every keyframe is reachable from the gauge (index 0).
    pub fn check_connected(&self) -> Result<(), GraphError> {
        if self.is_empty() {
            return Err(GraphError::Empty);
        }
        let seen = self.reachable_from_gauge();
        match seen.iter().position(|s| !s) {
            None => Ok(()),
            Some(k) => Err(GraphError::NotConnected {
                unreachable: self.id_of(k),
                gauge: self.id_of(0),
            }),
        }
    }

    fn reachable_from_gauge(&self) -> Vec<bool> {
        let adj = self.adjacency();
        let mut seen = vec![false; self.len()];
        let mut queue = VecDeque::from([0usize]);
        seen[0] = true;
        while let Some(k) = queue.pop_front() {
            for &(n, _) in &adj[k] {
                if !seen[n] {
                    seen[n] = true;
                    queue.push_back(n);
                }
            }
        }
        seen
    }

    /// Poses composed along a breadth-first spanning tree from the gauge,
    /// odometry edges first: the classic "initial guess from odometry".
    pub fn compose_spanning_tree(&self) -> Result<Vec<P>, GraphError> {
        self.check_connected()?;
        let mut adj = self.adjacency();
        for list in &mut adj {
            list.sort_by_key(|&(_, e)| (self.edges[e].kind != EdgeKind::Odometry, e));
        }
        let mut poses: Vec<Option<P>> = vec![None; self.len()];
        poses[0] = Some(P::IDENTITY);
        let mut queue = VecDeque::from([0usize]);
        while let Some(k) = queue.pop_front() {
            let pk = poses[k].unwrap_or_default();
            for &(n, e) in &adj[k] {
                if poses[n].is_none() {
                    let edge = &self.edges[e];
                    let rel = if edge.from == k {
                        edge.measurement
                    } else {
                        edge.measurement.inverse()
                    };
                    poses[n] = Some(pk.compose(&rel));
                    queue.push_back(n);
                }
            }
        }
        Ok(poses.into_iter().map(|p| p.unwrap_or_default()).collect())
    }

    /// The initial guess of the source (its `VERTEX` lines) where every
    /// keyframe has one, else the spanning-tree composition.
    pub fn initial_guess(&self) -> Result<Vec<P>, GraphError> {
        let guesses: Option<Vec<P>> = self.keyframes.iter().map(|k| k.guess).collect();
        match guesses {
            Some(g) if g.iter().any(|p| *p != P::IDENTITY) => Ok(g),
            _ => self.compose_spanning_tree(),
        }
    }
}

/// The fill-reducing order of the free keyframes `1..n` (keyframe `k` is
/// unknown `k − 1`): AMD on the graph of `edges`. Every normal matrix slamd
/// builds over these keyframes (axes, positions, Gauss–Newton blocks) has
/// this graph as its pattern, so one ordering serves them all.
pub fn pose_ordering<P: RigidMotion>(n: usize, edges: &[Edge<P>]) -> Vec<usize> {
    let free = edges
        .iter()
        .filter(|e| e.from > 0 && e.to > 0)
        .map(|e| (e.from - 1, e.to - 1));
    crate::sparse::ordering::amd_of_pairs(n.saturating_sub(1), free)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(n: u64) -> PoseGraph {
        let mut g = PoseGraph::default();
        for id in 0..n {
            g.add_keyframe(id, None).unwrap();
        }
        for id in 1..n {
            g.add_edge(
                id - 1,
                id,
                Pose2::new(1.0, 0.0, 0.1),
                Information::identity(),
                EdgeKind::Odometry,
            )
            .unwrap();
        }
        g
    }

    #[test]
    fn rejects_bad_keyframes_and_edges() {
        let mut g = chain(3);
        assert_eq!(g.add_keyframe(1, None), Err(GraphError::DuplicateKeyframe(1)));
        let info = Information::identity();
        assert_eq!(
            g.add_edge(0, 7, Pose2::IDENTITY, info, EdgeKind::LoopClosure),
            Err(GraphError::UnknownKeyframe(7))
        );
        assert_eq!(
            g.add_edge(2, 2, Pose2::IDENTITY, info, EdgeKind::Other),
            Err(GraphError::SelfEdge(2))
        );
        assert_eq!(
            g.add_edge(0, 2, Pose2::new(f64::NAN, 0.0, 0.0), info, EdgeKind::LoopClosure),
            Err(GraphError::NonFinite("edge measurement"))
        );
        assert_eq!(g.edges().len(), 2, "rejected edges must not be stored");
    }

    #[test]
    fn detects_disconnected_keyframes() {
        let mut g = chain(3);
        g.add_keyframe(9, None).unwrap();
        assert_eq!(
            g.check_connected(),
            Err(GraphError::NotConnected {
                unreachable: 9,
                gauge: 0
            })
        );
    }

    #[test]
    fn time_order_sorts_by_newer_then_older() {
        let mut g = chain(4);
        g.add_edge(
            3,
            0,
            Pose2::IDENTITY,
            Information::identity(),
            EdgeKind::LoopClosure,
        )
        .unwrap();
        g.add_edge(1, 2, Pose2::IDENTITY, Information::identity(), EdgeKind::Odometry)
            .unwrap();
        // edges: 0:(0,1) 1:(1,2) 2:(2,3) 3:(3,0) 4:(1,2)
        assert_eq!(g.time_order(), vec![0, 1, 4, 3, 2]);
        assert_eq!(g.by_newer(), vec![vec![], vec![0], vec![1, 4], vec![3, 2]]);
    }

    #[test]
    fn spanning_tree_composes_odometry() {
        let g = chain(3);
        let p = g.compose_spanning_tree().unwrap();
        let expected = Pose2::new(1.0, 0.0, 0.1).compose(&Pose2::new(1.0, 0.0, 0.1));
        assert!((p[2].x - expected.x).abs() < 1e-15 && (p[2].theta - 0.2).abs() < 1e-15);
    }
}
