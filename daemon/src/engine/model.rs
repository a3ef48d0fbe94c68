//! [`Model`]: the graph and everything the engine knows about it besides
//! the factor: weights and switches, which keyframes joined, which edges
//! wait, GPS fixes and the georeference; and the re-solve's work on it
//! (robust polish, georeferencing).

use super::op::Polish;
use super::pose::EnginePose;
use super::EngineConfig;
use crate::geometry::Pose2;
use crate::gps::{variance_factor, Georef, GpsConfig, GpsFix, GpsInput};
use crate::graph::{chi2_of_edges, Edge, InformationMatrix, PoseGraph};
use crate::nonlinear::{LevenbergMarquardtParams, PositionPrior};
use crate::outliers::consistency::ConsistencyGraph;
use crate::outliers::cycles;
use crate::outliers::{robust_polish, Comparison, OutlierConfig, RobustEdges, OFF_BELOW, REJECTED_BELOW};
use slamd_protocol::codec::Origin;
use std::any::Any;
use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// [`Polish::Inline`] stops once an accepted step lowers the robust cost by
/// less than this fraction, where the re-solves polish to
/// `config.polish`'s tolerance. Its estimate only bridges to the next
/// background re-solve, and a keyframe waits for it: on W10000 its
/// polishes took 11–35 iterations to 10⁻⁹ where 3–5 reach 10⁻⁴.
pub const INLINE_RELATIVE_TOL: f64 = 1e-4;

/// What the engine holds of one edge besides its measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeState {
    /// The weight set through the engine (1 unless reweighted; 0 removes).
    pub scale: f64,
    /// The outlier filter's switch `s ∈ [0, 1]` (1 for odometry).
    pub switch: f64,
    /// A loop closure let in on arrival (by its own error or by the gate's
    /// pairing) since the last multi-start re-solve, which gets a start
    /// without them.
    pub admitted: bool,
    /// Its terms are in the factor.
    pub applied: bool,
    /// Who sent it (what a saved map and the switch list report).
    pub origin: Origin,
}

impl EdgeState {
    /// A new edge: weight 1, switched on, not yet in the factor.
    pub const NEW: EdgeState = EdgeState {
        scale: 1.0,
        switch: 1.0,
        admitted: false,
        applied: false,
        origin: Origin::LOCAL,
    };

    /// A new loop closure held out (switch 0) until the judge decides it.
    pub const HELD: EdgeState = EdgeState {
        switch: 0.0,
        ..EdgeState::NEW
    };

    /// The multiplier of the edge's information: `scale · s²`, or 0 when
    /// the switch is off ([`OFF_BELOW`]).
    pub fn weight(&self) -> f64 {
        let s = self.switch;
        if s < OFF_BELOW {
            0.0
        } else {
            self.scale * s * s
        }
    }
}

/// What the engine holds of one keyframe.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KeyframeState {
    /// Linked to the gauge keyframe through applied edges: in the estimate.
    pub joined: bool,
    /// The applied edges at it.
    pub incident: Vec<u32>,
    /// When the frontend took it (ns on its clock; 0: not given).
    pub timestamp_ns: u64,
}

/// What the engine holds of one GPS fix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixState {
    /// The fix, in the local ENU frame.
    pub fix: GpsFix,
    /// Its prior is in the Gauss–Newton system.
    pub applied: bool,
}

/// The graph and its bookkeeping, without the factor.
#[derive(Clone, Debug, Default)]
pub struct Model<P: EnginePose = Pose2> {
    /// Keyframes in arrival order (index 0 is the gauge) and every edge.
    pub graph: PoseGraph<P>,
    /// What the engine holds of each edge, by index.
    pub edges: Vec<EdgeState>,
    /// What the engine holds of each keyframe, by index.
    pub keyframes: Vec<KeyframeState>,
    /// Edges waiting for a keyframe to join, by keyframe.
    pub waiting: HashMap<usize, Vec<usize>>,
    /// Edges received but not yet connected to the factor (that happens at
    /// the next solve, odometry first).
    pub unconnected: Vec<usize>,
    /// GPS fixes, in arrival order.
    pub fixes: Vec<FixState>,
    /// The map→ENU motion of the last re-solve (with two or more fixes).
    pub georef: Option<Georef>,
    /// The weight of every GPS prior (the graph's variance factor).
    pub gps_weight: f64,
    /// Loop closures wait for a judge's decision, held out
    /// ([`EdgeState::HELD`]), rather than pass the arrival gate: the
    /// publishing engine's model.
    pub judged: bool,
    /// The pairwise consistency of the loop closures. It depends on the
    /// input alone, so every copy of the model (a background re-solve's)
    /// shares and extends the one graph.
    pub consistency: Arc<Mutex<ConsistencyGraph>>,
}

impl<P: EnginePose> Model<P> {
    /// The multiplier of edge `e`'s information: `scale · s²`, or 0 when
    /// the switch is off ([`OFF_BELOW`]).
    pub fn weight(&self, e: usize) -> f64 {
        self.edges[e].weight()
    }

    /// Whether keyframe `k` has joined the estimate.
    pub fn joined(&self, k: usize) -> bool {
        self.keyframes[k].joined
    }

    /// Whether each keyframe has joined, by index.
    pub fn joined_flags(&self) -> Vec<bool> {
        self.keyframes.iter().map(|k| k.joined).collect()
    }

    /// Edge `e` waits for keyframe `k` to join (once).
    pub(super) fn wait_for(&mut self, k: usize, e: usize) {
        let list = self.waiting.entry(k).or_default();
        if !list.contains(&e) {
            list.push(e);
        }
    }

    /// The prior of fix `f` under the current georeference.
    pub(super) fn prior(&self, f: usize) -> Option<PositionPrior<P>> {
        let g = self.georef.as_ref()?;
        Some(P::gps_prior(&self.fixes[f].fix, g, self.gps_weight))
    }
}

impl<P: EnginePose> Model<P> {
    /// The applied edges of nonzero scale over compact keyframe indices,
    /// their information scaled by `weight(model, e)`, with their indices.
    pub(super) fn compact_edges(
        &self,
        compact: &[usize],
        weight: impl Fn(&Self, usize) -> f64,
    ) -> (Vec<Edge<P>>, Vec<usize>) {
        let ids: Vec<usize> = (0..self.graph.edges().len())
            .filter(|&e| self.edges[e].applied && self.edges[e].scale > 0.0)
            .collect();
        let edges = ids
            .iter()
            .map(|&e| {
                let mut edge = self.graph.edges()[e];
                edge.information = edge.information.scaled(weight(self, e));
                edge.from = compact[edge.from];
                edge.to = compact[edge.to];
                edge
            })
            .collect();
        (edges, ids)
    }

    /// The joined keyframes (gauge first) and the compact index of every
    /// keyframe among them (`usize::MAX` where not joined).
    pub(super) fn compact_joined(&self) -> (Vec<usize>, Vec<usize>) {
        let joined: Vec<usize> = (0..self.graph.len()).filter(|&k| self.joined(k)).collect();
        let mut compact = vec![usize::MAX; self.graph.len()];
        for (c, &k) in joined.iter().enumerate() {
            compact[k] = c;
        }
        (joined, compact)
    }

    /// The re-solve's polish ([`robust_polish`]). [`Polish::Full`] (and
    /// [`Polish::FullInline`] and [`Polish::Closing`], two starts at a
    /// time) starts from the current estimate and from the two-stage
    /// solutions with and without the switches: after a large loop closure
    /// the estimate can sit in the wrong basin, and the two-stage
    /// solution does not depend on it ([`Self::starts`]; the closing one
    /// also without the loop closures let in on arrival, and without any:
    /// the dead-reckoned map). [`Polish::Inline`]
    /// starts from the estimate alone and stops at [`INLINE_RELATIVE_TOL`].
    /// Sets every switch from the result; returns the poses (compact
    /// indices). Once `stop` is set the polish ends where it is.
    pub(super) fn robust_polish(
        &mut self,
        config: &EngineConfig,
        compact: &[usize],
        joined: &[usize],
        lin: &[P],
        polish: Polish,
        stop: &AtomicBool,
    ) -> Vec<P> {
        let filter = &config.outliers;
        // with the filter off the switches stand (a judge's, or none): the
        // edges weigh what they weigh, and the polish is plain
        let (edges, ids) = if filter.enabled {
            self.compact_edges(compact, |m, e| m.edges[e].scale)
        } else {
            let (edges, ids) = self.compact_edges(compact, Self::weight);
            // held out or switched off: no fill for nothing
            (edges.into_iter().zip(ids))
                .filter(|(_, e)| self.weight(*e) > 0.0)
                .unzip()
        };
        let switchable: Vec<bool> = ids
            .iter()
            .map(|&e| filter.switchable(&self.graph.edges()[e]))
            .collect();
        let initial: Vec<P> = joined.iter().map(|&k| lin[k]).collect();
        // paper A's cycle test, on planar graphs
        let cycle_rejected = (&edges as &dyn Any)
            .downcast_ref::<Vec<Edge>>()
            .map(|edges| cycles::rejected(initial.len(), edges, &switchable, filter));
        debug_assert!(P::DIMENSION != 2 || cycle_rejected.is_some());
        let held_out = cycles::either(
            self.held_out(filter, &ids, &switchable),
            cycle_rejected.unwrap_or_default(),
        );
        let starts = self.starts(config, compact, joined, &initial, &ids, polish);
        let threads = if matches!(polish, Polish::FullInline | Polish::Closing) {
            2
        } else {
            1
        };
        let input = RobustEdges {
            edges: &edges,
            switchable: &switchable,
            held_out: &held_out,
        };
        let mut lm = config.polish;
        if polish == Polish::Inline {
            lm.relative_error_tol = lm.relative_error_tol.max(INLINE_RELATIVE_TOL);
        }
        let Ok(solution) = robust_polish(
            input,
            starts,
            filter,
            lm,
            threads,
            Some(stop),
            Comparison::AtFirstStart,
        ) else {
            return initial;
        };
        if filter.enabled {
            for (a, &e) in ids.iter().enumerate() {
                self.edges[e].switch = solution.switches[a];
            }
        }
        if matches!(polish, Polish::Full | Polish::FullInline | Polish::Closing) {
            self.edges.iter_mut().for_each(|s| s.admitted = false);
        }
        solution.poses
    }

    /// Which of the edges `ids` (graph indices; `switchable` alike) PCM
    /// holds out: the switchable ones outside the largest consistent set
    /// among them ([`ConsistencyGraph`]), when the filter asks for it and
    /// the graph is planar (else none: an empty list).
    fn held_out(&self, filter: &OutlierConfig, ids: &[usize], switchable: &[bool]) -> Vec<bool> {
        let planar = (&self.graph as &dyn Any).downcast_ref::<PoseGraph>();
        debug_assert!(P::DIMENSION != 2 || planar.is_some());
        let (true, Some(graph)) = (filter.pcm(), planar) else {
            return Vec::new();
        };
        let edges = graph.edges();
        let mut pcm = self.consistency.lock().unwrap_or_else(|e| e.into_inner());
        pcm.update(
            graph.len(),
            edges,
            |e| filter.switchable(&edges[e]),
            filter.pairwise_chi2,
        );
        pcm.held_out(ids, switchable)
    }

    /// The starts of [`Self::robust_polish`] (`ids`: the graph indices of
    /// the edges it polishes): the estimate `initial` (compact), then, for a
    /// multi-start polish, the two-stage solutions described inline.
    pub(super) fn starts(
        &self,
        config: &EngineConfig,
        compact: &[usize],
        joined: &[usize],
        initial: &[P],
        ids: &[usize],
        polish: Polish,
    ) -> Vec<Vec<P>> {
        let mut starts = vec![initial.to_vec()];
        if matches!(polish, Polish::Full | Polish::FullInline | Polish::Closing) {
            // the two-stage solution under the current switches, and (when
            // some are below 1) under none: a loop closure switched off on
            // arrival against a drifted estimate must get a start that does
            // not already exclude it.
            // A scheduled re-solve takes that start only while some loop
            // closure is held wrong (below 0.5): the pessimistic weights of
            // most datasets leave a few true ones a little below 1, and no
            // refresh lands while a longer re-solve runs
            starts.extend(self.linear_start(compact, joined, initial[0], Self::weight));
            let rescue_below = if polish == Polish::Full {
                REJECTED_BELOW
            } else {
                1.0
            };
            let filtered = config.outliers.enabled;
            if filtered && ids.iter().any(|&e| self.edges[e].switch < rescue_below) {
                starts.extend(self.linear_start(compact, joined, initial[0], |m, e| m.edges[e].scale));
            }
            // and, closing (or always, `unadmitted_start`), without the
            // loop closures let in on arrival since the last of these
            // re-solves: a group of agreeing wrong ones can meet a map bent
            // by the ones before it, and every other start then ends in
            // their basin
            let unadmitted_due = polish == Polish::Closing || config.outliers.unadmitted_start;
            if unadmitted_due && ids.iter().any(|&e| self.edges[e].admitted) {
                let unadmitted = |m: &Self, e: usize| if m.edges[e].admitted { 0.0 } else { m.weight(e) };
                starts.extend(self.linear_start(compact, joined, initial[0], unadmitted));
            }
            // and, closing, the dead-reckoned map: the two-stage solution
            // under no switchable loop closure. Wrong loop closures let in
            // mid-stream can have bent every other start, not this one. It
            // equals the start before (with none let in on arrival, the one
            // under the switches) unless a loop closure a re-solve let in
            // weighs in, so only then
            let outliers = &config.outliers;
            let switched = |m: &Self, e: usize| outliers.switchable(&m.graph.edges()[e]);
            let weighed_in =
                |&e: &usize| switched(self, e) && !self.edges[e].admitted && self.weight(e) > 0.0;
            if polish == Polish::Closing && ids.iter().any(weighed_in) {
                let dead_reckoned = |m: &Self, e: usize| if switched(m, e) { 0.0 } else { m.weight(e) };
                starts.extend(self.linear_start(compact, joined, initial[0], dead_reckoned));
            }
        }
        starts
    }

    /// The two-stage solution over the joined keyframes with each edge's
    /// information scaled by `weight`, moved to the gauge's pose.
    fn linear_start(
        &self,
        compact: &[usize],
        joined: &[usize],
        gauge: P,
        weight: impl Fn(&Self, usize) -> f64,
    ) -> Option<Vec<P>> {
        let keyframes: Vec<_> = joined.iter().map(|&k| self.graph.keyframes()[k]).collect();
        let (weighted, _) = self.compact_edges(compact, weight);
        let weighted = weighted
            .into_iter()
            .filter(|e| !e.information.is_zero())
            .collect();
        let linear = P::linear_solution(&PoseGraph::from_parts(keyframes, weighted).ok()?)?;
        Some(linear.iter().map(|p| gauge.compose(p)).collect())
    }

    /// With two or more fixes on the joined keyframes: sets the GPS weight
    /// from the polished graph's χ², fits the georeference to `poses`
    /// (compact: `compact[k]` is keyframe `k`'s index), polishes with the
    /// fixes as priors and refits, twice ([`GpsInput::georeference`](crate::gps::GpsInput::georeference)).
    pub(super) fn georeference(
        &mut self,
        config: &GpsConfig,
        edges: &[Edge<P>],
        compact: &[usize],
        poses: &mut Vec<P>,
        params: &LevenbergMarquardtParams,
    ) {
        let fixes: Vec<GpsFix> = (self.fixes.iter())
            .filter(|f| self.joined(f.fix.keyframe))
            .map(|f| GpsFix {
                keyframe: compact[f.fix.keyframe],
                ..f.fix
            })
            .collect();
        if !config.absolute || fixes.len() < 2 {
            return;
        }
        let mut input = GpsInput::with_config(fixes, config);
        if config.calibrate {
            input.weight = variance_factor(chi2_of_edges(edges, poses), edges.len(), poses.len(), P::DOF);
        }
        // a polish that fails ends the rounds with the fit it started from:
        // repeating it from the same poses would fail the same way
        let mut georef = None;
        let _ = input.georeference(edges, poses, &mut georef, *params, 2);
        if let Some(g) = georef {
            self.georef = Some(g);
            self.gps_weight = input.weight;
        }
    }

    /// Keyframes (other than the gauge) left without any weighted edge are
    /// put back to waiting, with their edges: they are unconstrained and
    /// would make the normal equations singular.
    pub(super) fn unjoin_unconstrained(&mut self) {
        loop {
            let mut degree = vec![0usize; self.graph.len()];
            for (e, edge) in self.graph.edges().iter().enumerate() {
                if self.edges[e].applied && self.weight(e) > 0.0 {
                    degree[edge.from] += 1;
                    degree[edge.to] += 1;
                }
            }
            let lonely: Vec<usize> = (1..self.graph.len())
                .filter(|&k| self.joined(k) && degree[k] == 0)
                .collect();
            if lonely.is_empty() {
                return;
            }
            for k in lonely {
                self.keyframes[k].joined = false;
                for e in std::mem::take(&mut self.keyframes[k].incident) {
                    let e = e as usize;
                    self.edges[e].applied = false;
                    let edge = self.graph.edges()[e];
                    let other = if edge.from == k { edge.to } else { edge.from };
                    self.keyframes[other].incident.retain(|&x| x as usize != e);
                    for end in [k, other] {
                        self.waiting.entry(end).or_default().push(e);
                    }
                }
            }
        }
    }
}
