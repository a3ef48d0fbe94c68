//! The engine thread's state directory: a journal commit before each
//! snapshot, checkpoints, and the start from a saved map and the
//! journal's tail.
//!
//! Order of a batch: the messages are applied and their records buffered;
//! the journal is written (and fsynced as `state.sync` says); only then
//! does the snapshot go out with the acknowledgements. A commit that fails
//! (a full disk) leaves the acknowledgements where they were and is tried
//! again at every tick; the records stay buffered, so nothing taken is
//! lost while the daemon lives.

use super::acks::Acks;
use super::engine_loop::EngineLoop;
use crate::engine::{Engine, EngineError, EnginePose};
use crate::store::{Cut, MapEdge, MapFile, MapKeyframe, Record, StateDir};
use slamd_types::KeyframeId;
use std::collections::{HashMap, HashSet};
use std::time::{Duration, Instant};

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
        self.store = start.store;
        if let Some(cut) = &start.cut {
            tracing::warn!(
                offset = cut.offset,
                reason = %cut.reason,
                "The journal ends in a damaged record; it and what follows are cut off."
            );
        }
        let saved = start.map.is_some();
        let mut map = start.map.unwrap_or_default();
        self.acks = Acks::from_saved(&map.acks);
        let mut fold = Fold::new(&map);
        for r in std::mem::take(&mut map.held) {
            fold.record(&mut map, r);
        }
        let tail = start.tail.len();
        for r in start.tail {
            if self.acks.take(r.origin()) {
                fold.record(&mut map, r);
            }
        }
        self.acks.seal();
        fold.held = fold.waiting.drain().flat_map(|(_, v)| v).collect();
        if !saved && map.keyframes.is_empty() && fold.held.is_empty() {
            self.durable = self.acks.header();
            return Ok(());
        }
        self.engine = Engine::restore(self.config.engine(), &map, tail > 0)?;
        self.edge_origin = map.edges.iter().map(|e| e.origin).collect();
        self.counters.keyframes = map.keyframes.len() as u64;
        self.counters.edges = map.edges.len() as u64;
        self.counters.fixes = map.fixes.len() as u64;
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
        self.durable = self.acks.header();
        self.dirty = true;
        Ok(())
    }

    /// Writes the buffered records; on success the acknowledgements
    /// advance to what was taken.
    pub(super) fn commit(&mut self) {
        let Some(store) = &mut self.store else {
            self.durable = self.acks.header();
            return;
        };
        match store.journal().commit() {
            Ok(()) => {
                if self.store_failed {
                    tracing::info!("The journal is written again; acknowledgements resume.");
                }
                self.store_failed = false;
                self.durable = self.acks.header();
            }
            Err(e) => {
                if !self.store_failed {
                    tracing::error!(error = %e, "Cannot write the journal; acknowledgements wait.");
                }
                self.store_failed = true;
            }
        }
    }

    /// A checkpoint when the journal is large or the interval has passed
    /// since the last one with records in between.
    pub(super) fn checkpoint_if_due(&mut self) {
        let Some(store) = &mut self.store else {
            return;
        };
        let interval = Duration::from_secs_f64(self.config.state.checkpoint_interval_s.max(0.0));
        let due = store.journal_full()
            || (self.last_checkpoint.elapsed() >= interval && !store.journal().is_empty());
        if due {
            self.checkpoint();
        }
    }

    /// Writes the whole map and starts a new journal.
    pub(super) fn checkpoint(&mut self) {
        let t0 = Instant::now();
        let mut map = self.engine.map();
        for (e, o) in map.edges.iter_mut().zip(&self.edge_origin) {
            e.origin = *o;
        }
        map.acks = self.acks.saved();
        map.held = (self.held.waiting())
            .map(|h| Record::Edge(h.origin, h.item))
            .chain(self.held_fixes.waiting().map(|h| Record::Fix(h.origin, h.item)))
            .collect();
        let Some(store) = &mut self.store else {
            return;
        };
        self.last_checkpoint = Instant::now();
        match store.checkpoint(map) {
            Ok(()) => {
                self.store_failed = false;
                self.durable = self.acks.header();
                self.checkpoint_at_ns = super::engine_loop::now_ns();
                tracing::debug!(seconds = t0.elapsed().as_secs_f64(), "Checkpoint written.");
            }
            Err(e) => tracing::error!(error = %e, "Cannot write a checkpoint; the journal goes on."),
        }
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
            Record::Keyframe(_, id, guess, timestamp_ns) => {
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
