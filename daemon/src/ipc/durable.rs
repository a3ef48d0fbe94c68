//! The engine loop's start from a saved map and the journal's tail, and
//! its checkpoints: the map it holds, with what waits, handed to
//! [`Durability`](super::durability::Durability).

use super::acks::Acks;
use super::engine_loop::EngineLoop;
use crate::engine::{Engine, EngineError, EnginePose};
use crate::store::{Cut, MapEdge, MapFile, MapKeyframe, Record, StateDir};
use slamd_types::{KeyframeId, KeyframeInput};
use std::collections::{HashMap, HashSet};
use std::time::Instant;

/// What the engine thread starts from.
pub struct Start<P: EnginePose> {
    /// The state directory, opened.
    pub store: Option<StateDir>,
    /// The map to continue: the directory's checkpoint or `--map`.
    pub map: Option<MapFile<P>>,
    /// The journal's records after the map.
    pub tail: Vec<Record<P>>,
    /// Where the journal was cut.
    pub cut: Option<Cut>,
}

impl<P: EnginePose> EngineLoop<P> {
    /// Takes up `start`: the journal's tail is folded into the map as the
    /// daemon would have applied it (a repeated keyframe refused, an edge
    /// or fix held until its keyframe is there), then the engine is built
    /// from the whole in one step, polished once when the tail added
    /// anything. Nothing is journaled again.
    pub fn take_up(&mut self, start: Start<P>) -> Result<(), EngineError> {
        let t0 = Instant::now();
        let d = &mut self.durability;
        d.store = start.store;
        if let Some(cut) = &start.cut {
            tracing::warn!(
                offset = cut.offset,
                reason = %cut.reason,
                "The journal ends in a damaged record; it and what follows are cut off."
            );
        }
        let saved = start.map.is_some();
        let mut map = start.map.unwrap_or_default();
        d.acks = Acks::from_saved(&map.acks);
        let mut fold = Fold::new(&map);
        for r in std::mem::take(&mut map.held) {
            fold.record(&mut map, r);
        }
        let tail = start.tail.len();
        for r in start.tail {
            if d.acks.take(r.origin()) {
                fold.record(&mut map, r);
            }
        }
        d.acks.seal();
        fold.held = fold.waiting.drain().flat_map(|(_, v)| v).collect();
        if !saved && map.keyframes.is_empty() && fold.held.is_empty() {
            d.acknowledged = d.acks.header();
            return Ok(());
        }
        self.counters.keyframes = map.keyframes.len() as u64;
        self.counters.edges = map.edges.len() as u64;
        self.counters.fixes = map.fixes.len() as u64;
        self.engine = Engine::restore(self.config.engine(), map, tail > 0)?;
        self.counters.rejected += fold.refused;
        self.recovering = true;
        for r in fold.held {
            match r {
                Record::Edge(o, e) => self.add_edge(o, e, Instant::now()),
                Record::Fix(o, f) => self.add_gps(o, f, Instant::now()),
                _ => {}
            }
        }
        self.recovering = false;
        tracing::info!(
            keyframes = self.counters.keyframes,
            edges = self.counters.edges,
            journal_records = tail,
            seconds = t0.elapsed().as_secs_f64(),
            "Map restored."
        );
        // what was acknowledged before is acknowledged again at once, and
        // the restored map goes out
        self.durability.acknowledged = self.durability.acks.header();
        self.dirty = true;
        Ok(())
    }

    /// Writes the whole map, with the messages still held, and starts a
    /// new journal.
    pub(super) fn checkpoint(&mut self) {
        if !self.durability.stored() {
            return;
        }
        let mut map = self.engine.map();
        map.held = (self.held.waiting())
            .map(|h| Record::Edge(h.origin, h.item))
            .chain(self.held_fixes.waiting().map(|h| Record::Fix(h.origin, h.item)))
            .collect();
        self.durability.checkpoint(map);
    }
}

/// Journal records folded into a map as the engine thread would have
/// applied them one by one.
struct Fold<P: EnginePose> {
    ids: HashSet<KeyframeId>,
    /// Edges and fixes waiting for a keyframe, by its id.
    waiting: HashMap<KeyframeId, Vec<Record<P>>>,
    /// Still waiting at the end.
    held: Vec<Record<P>>,
    /// Records the engine would have refused.
    refused: u64,
}

impl<P: EnginePose> Fold<P> {
    fn new(map: &MapFile<P>) -> Self {
        Self {
            ids: map.keyframes.iter().map(|k| k.id).collect(),
            waiting: HashMap::new(),
            held: Vec::new(),
            refused: 0,
        }
    }

    fn record(&mut self, map: &mut MapFile<P>, r: Record<P>) {
        match r {
            Record::Keyframe(
                _,
                KeyframeInput {
                    id,
                    guess,
                    timestamp_ns,
                },
            ) => {
                if !self.ids.insert(id) {
                    self.refused += 1;
                    return;
                }
                let at = guess.unwrap_or(P::IDENTITY);
                map.keyframes.push(MapKeyframe {
                    id,
                    guess,
                    estimate: at,
                    lin: at,
                    joined: false,
                    timestamp_ns,
                });
                for w in self.waiting.remove(&id).unwrap_or_default() {
                    self.record(map, w);
                }
            }
            Record::Edge(_, e) if e.from == e.to => self.refused += 1,
            Record::Edge(o, e) => match [e.from, e.to].into_iter().find(|k| !self.ids.contains(k)) {
                Some(missing) => self.waiting.entry(missing).or_default().push(r),
                None => map.edges.push(MapEdge {
                    edge: e,
                    scale: 1.0,
                    // the outlier filter has yet to decide it
                    switch: if e.kind.switchable() { 0.0 } else { 1.0 },
                    pending: e.kind.switchable(),
                    origin: o,
                }),
            },
            Record::Fix(_, f) if f.check().is_err() => self.refused += 1,
            Record::Fix(_, f) => {
                if self.ids.contains(&f.keyframe) {
                    map.fixes.push(f);
                } else {
                    self.waiting.entry(f.keyframe).or_default().push(r);
                }
            }
            Record::Refused(_) => {}
        }
    }
}
