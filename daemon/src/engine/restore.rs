//! A [`State`] from a saved map in one step, and a saved map from a
//! state: what a restart and `slamd run --map` start from.
//!
//! The model is rebuilt as the engine built it: keyframes and edges in
//! arrival order, each edge with its weight and switch. Keyframes join as
//! [`State::apply`]'s connect would have joined them (a breadth-first walk
//! from the gauge over edges of nonzero weight); an edge with both ends
//! joined is applied, any other waits for its missing end. The factor is
//! then built once at the saved linearisation point ([`factorise`]), so
//! the first solve gives the saved estimate again: no polish, no
//! incremental updates, so a City10000-sized map is back in a fraction of
//! a second. A map with keyframes and edges its estimate does not cover
//! yet (a journal's tail folded in) gets one re-solve's robust polish
//! first ([`rebuild`]).

use super::judge;
use super::model::{EdgeState, FixState, KeyframeState, Model};
use super::op::Polish;
use super::rebuild::rebuild;
use super::state::State;
use super::{Engine, EngineConfig, EngineError, EnginePose, FixInput};
use crate::gps::{Geodetic, GpsFix, LocalFrame};
use crate::store::{MapEdge, MapFile, MapKeyframe, SavedGeoref};
use std::collections::VecDeque;

/// The state of `map`'s graph, with its GPS fixes in `frame`, polished
/// as `polish` says before the factor is built. A pending loop closure is
/// held out (switch 0) when `judged` (beside a judge), else on (switch 1,
/// as a new edge before the arrival gate).
pub(super) fn state_of<P: EnginePose>(
    map: &MapFile<P>,
    frame: Option<LocalFrame>,
    polish: Polish,
    config: &EngineConfig,
    judged: bool,
) -> Result<State<P>, EngineError> {
    let mut model = Model {
        judged,
        ..Model::default()
    };
    let mut lin = Vec::with_capacity(map.keyframes.len());
    for k in &map.keyframes {
        model.graph.add_keyframe(k.id, k.guess)?;
        model.keyframes.push(KeyframeState {
            timestamp_ns: k.timestamp_ns,
            ..KeyframeState::default()
        });
        lin.push(k.lin);
    }
    for e in &map.edges {
        let i = &e.edge;
        model
            .graph
            .add_edge(i.from, i.to, i.measurement, i.information, i.kind)?;
        let switch = match (e.pending, judged) {
            (true, true) => 0.0,
            (true, false) => 1.0,
            (false, _) => e.switch,
        };
        model.edges.push(EdgeState {
            scale: e.scale,
            switch,
            origin: e.origin,
            ..EdgeState::NEW
        });
    }
    join(&mut model, &mut lin, map);
    for f in &map.fixes {
        let fix = fix_of(f, &model, frame)?;
        model.fixes.push(FixState { fix, applied: false });
    }
    if let Some(g) = map.georef {
        model.georef = Some(g.georef);
        model.gps_weight = g.weight;
    }
    let state = if polish == Polish::None {
        State::factorise(model, lin, config)
    } else {
        rebuild(model, &lin, polish, config)
    };
    state.map_err(|e| EngineError::Restore(e.to_string()))
}

/// Joins the keyframes linked to the gauge, applies the edges between
/// joined keyframes and makes the others wait. A keyframe the map had not
/// joined starts at its guess, else composed from the keyframe it joins
/// through.
fn join<P: EnginePose>(model: &mut Model<P>, lin: &mut [P], map: &MapFile<P>) {
    let n = model.graph.len();
    if n == 0 {
        return;
    }
    let adjacency = model.graph.adjacency();
    let mut queue = VecDeque::from([0]);
    model.keyframes[0].joined = true;
    while let Some(m) = queue.pop_front() {
        for &(k, e) in &adjacency[m] {
            if model.joined(k) || model.edges[e].weight() == 0.0 {
                continue;
            }
            model.keyframes[k].joined = true;
            if !map.keyframes[k].joined {
                let edge = &model.graph.edges()[e];
                let rel = if edge.from == m {
                    edge.measurement
                } else {
                    edge.measurement.inverse()
                };
                lin[k] = model.graph.keyframes()[k]
                    .guess
                    .unwrap_or_else(|| lin[m].compose(&rel));
            }
            queue.push_back(k);
        }
    }
    for e in 0..model.graph.edges().len() {
        let (i, j) = (model.graph.edges()[e].from, model.graph.edges()[e].to);
        match (model.joined(i), model.joined(j)) {
            (true, true) => {
                model.edges[e].applied = true;
                model.keyframes[i].incident.push(e as u32);
                model.keyframes[j].incident.push(e as u32);
            }
            (ji, jj) => {
                if !ji {
                    model.wait_for(i, e);
                }
                if !jj {
                    model.wait_for(j, e);
                }
            }
        }
    }
}

/// A fix as the engine holds it: its keyframe's index, ENU position and
/// covariance.
fn fix_of<P: EnginePose>(
    f: &FixInput,
    model: &Model<P>,
    frame: Option<LocalFrame>,
) -> Result<GpsFix, EngineError> {
    let position = GpsFix::checked_position(f).map_err(EngineError::Gps)?;
    let k = (model.graph.index_of(f.keyframe)).ok_or(EngineError::FixKeyframe(f.keyframe))?;
    let frame = frame.unwrap_or_else(|| LocalFrame::new(position));
    Ok(GpsFix::at(f, &position, k, &frame))
}

/// The map `state` holds, with each keyframe's timestamp, each edge's
/// origin and the loop closures still `pending` (the acknowledgements and
/// the held messages are the daemon's to fill in).
pub(super) fn map_of<P: EnginePose>(
    state: &State<P>,
    origin: Option<Geodetic>,
    fixes: &[FixInput],
    pending: impl Fn(usize) -> bool,
) -> MapFile<P> {
    let m = &state.model;
    let (estimate, lin) = (state.estimate(), state.linearisation());
    // the linearisation covers the keyframes up to the newest joined one: a
    // keyframe whose edges never came (its frontend died) has none
    let keyframes = (m.graph.keyframes().iter().enumerate())
        .map(|(k, kf)| MapKeyframe {
            id: kf.id,
            guess: kf.guess,
            estimate: estimate[k],
            lin: lin.get(k).copied().unwrap_or(estimate[k]),
            joined: m.joined(k),
            timestamp_ns: m.keyframes[k].timestamp_ns,
        })
        .collect();
    let edges = (0..m.graph.edges().len())
        .map(|e| MapEdge {
            edge: m.graph.edge_input(e),
            scale: m.edges[e].scale,
            switch: m.edges[e].switch,
            pending: pending(e),
            origin: m.edges[e].origin,
        })
        .collect();
    MapFile {
        keyframes,
        edges,
        origin,
        georef: m.georef.map(|georef| SavedGeoref {
            georef,
            weight: m.gps_weight,
        }),
        fixes: fixes.to_vec(),
        ..MapFile::default()
    }
}

/// Saved maps.
impl<P: EnginePose> Engine<P> {
    /// An engine holding `map`: its keyframes, edges with their weights
    /// and switches, fixes and georeference, the factor built once at the
    /// saved linearisation point. With `polish` (keyframes or edges that
    /// the map's estimate does not cover yet), a re-solve's robust polish
    /// runs first, over everything. The map's GPS origin wins over the
    /// configured one (its fixes are relative to it).
    ///
    /// The map is taken by value: with the filter on and a background
    /// thread, the judge's own factorisation is built from it on that
    /// thread, and a copy would cost a map's worth of memory at the
    /// restart's peak.
    pub fn restore(
        config: EngineConfig,
        map: crate::store::MapFile<P>,
        polish: bool,
    ) -> Result<Self, EngineError> {
        if !config.outliers.enabled {
            return Self::restore_whole(config, &map, polish, false);
        }
        // the judge re-solves before it decides what was pending
        let pending: Vec<usize> = (0..map.edges.len()).filter(|&e| map.edges[e].pending).collect();
        let judge_polish = polish || !pending.is_empty();
        let mut engine = Self::restore_whole(judge::published_config(&config), &map, polish, true)?;
        let keyframes = engine.keyframe_count();
        engine.undecided = pending.into_iter().map(|e| (e, Some(keyframes))).collect();
        let judge_config = judge::judge_config(&config);
        if !config.background {
            let judge = Self::restore_whole(judge_config, &map, judge_polish, false)?;
            return Ok(Self::beside(engine, judge));
        }
        // the judge's own factorisation runs on its thread, off the path
        // to the first snapshot: a restart waits for one, not two
        let build = move || Self::restore_whole(judge_config, &map, judge_polish, false);
        Ok(Self::beside_restoring(engine, build))
    }

    /// [`Self::restore`] for an engine that applies its own filter, if on.
    /// `judged`: the publishing engine beside a judge.
    fn restore_whole(
        config: EngineConfig,
        map: &crate::store::MapFile<P>,
        polish: bool,
        judged: bool,
    ) -> Result<Self, EngineError> {
        let mut engine = Self::whole(config);
        if let Some(o) = map.origin {
            if engine.frame.is_some_and(|f| f.origin != o) {
                tracing::warn!(?o, "The saved map has its own GPS origin; using it.");
            }
            engine.frame = Some(LocalFrame::new(o));
        }
        if engine.frame.is_none() {
            // the first fix sets the origin, as in add_gps
            let first = map.fixes.first().map(|f| f.position);
            engine.frame = first
                .and_then(|p| Geodetic::new(p.lat, p.lon, p.height).ok())
                .map(LocalFrame::new);
        }
        let polish = if polish { Polish::Full } else { Polish::None };
        let state = state_of(map, engine.frame, polish, &engine.config, judged)?;
        engine.work_base = state.work();
        engine.schedule.fresh(&state);
        engine.schedule.polished(&state);
        engine.state = state;
        engine.fixes = map.fixes.clone();
        engine.version = 1;
        if polish == Polish::Full {
            engine.stats.resolves += 1;
        }
        Ok(engine)
    }

    /// The map as it stands: keyframes, edges with their weights and
    /// switches and origins, the estimate, the GPS origin, fixes and
    /// georeference. Acknowledgements and held messages are left empty.
    pub fn map(&self) -> crate::store::MapFile<P> {
        map_of(&self.state, self.gps_origin(), &self.fixes, |e| {
            self.is_pending(e)
        })
    }
}
