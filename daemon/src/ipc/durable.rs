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
use slamd_protocol::{FrontendAck, MAX_FRONTENDS};
use slamd_types::{KeyframeId, KeyframeInput};
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

/// What makes the daemon's input durable: which messages each frontend
/// has had taken, the state directory's journal and checkpoints, and the
/// acknowledgements snapshots carry, which never run ahead of the disk.
pub(super) struct Durability {
    /// What each frontend has had taken.
    acks: Acks,
    /// The acknowledgements snapshots carry: of what the journal holds
    /// (without a state directory, of what was taken).
    acknowledged: [FrontendAck; MAX_FRONTENDS],
    /// The state directory, if any.
    store: Option<StateDir>,
    /// The last journal commit failed; acknowledgements wait for one that
    /// does not.
    failing: bool,
    last_checkpoint: Instant,
    /// When it last wrote a checkpoint (ns since the UNIX epoch; 0: not
    /// yet).
    checkpoint_at_ns: u64,
    /// `state.checkpoint_interval_s`.
    interval: Duration,
}

impl Durability {
    pub(super) fn new(checkpoint_interval_s: f64) -> Self {
        Self {
            acks: Acks::default(),
            acknowledged: [FrontendAck::default(); MAX_FRONTENDS],
            store: None,
            failing: false,
            last_checkpoint: Instant::now(),
            checkpoint_at_ns: 0,
            interval: Duration::from_secs_f64(checkpoint_interval_s.max(0.0)),
        }
    }

    /// Takes `r`'s number and journals it (written at the next
    /// [`Self::commit`]); false for a message taken before.
    pub(super) fn admit<P: EnginePose>(&mut self, r: &Record<P>) -> bool {
        if !self.acks.take(r.origin()) {
            return false;
        }
        if let Some(store) = &mut self.store {
            store.journal().append(r);
        }
        true
    }

    /// The IPC thread has handed over everything it had.
    pub(super) fn seal(&mut self) {
        self.acks.seal();
    }

    /// Writes the buffered records; on success the acknowledgements
    /// advance to what was taken.
    pub(super) fn commit(&mut self) {
        let Some(store) = &mut self.store else {
            self.acknowledged = self.acks.header();
            return;
        };
        match store.journal().commit() {
            Ok(()) => {
                if self.failing {
                    tracing::info!("The journal is written again; acknowledgements resume.");
                }
                self.failing = false;
                self.acknowledged = self.acks.header();
            }
            Err(e) => {
                if !self.failing {
                    tracing::error!(error = %e, "Cannot write the journal; acknowledgements wait.");
                }
                self.failing = true;
            }
        }
    }

    /// fsyncs the journal when `state.sync` says it is due.
    pub(super) fn sync_if_due(&mut self) {
        if let Some(store) = &mut self.store {
            if let Err(e) = store.journal().sync_if_due() {
                tracing::error!(error = %e, "Cannot fsync the journal.");
            }
        }
    }

    /// A checkpoint is due: the journal is large, or the interval has
    /// passed since the last one with records in between.
    pub(super) fn checkpoint_due(&mut self) -> bool {
        let waited = self.last_checkpoint.elapsed() >= self.interval;
        (self.store.as_mut())
            .is_some_and(|store| store.journal_full() || (waited && !store.journal().is_empty()))
    }

    /// Writes `map` with the acknowledgements and starts a new journal.
    pub(super) fn checkpoint<P: EnginePose>(&mut self, mut map: MapFile<P>) {
        let t0 = Instant::now();
        map.acks = self.acks.saved();
        let Some(store) = &mut self.store else {
            return;
        };
        self.last_checkpoint = Instant::now();
        match store.checkpoint(map) {
            Ok(()) => {
                self.failing = false;
                self.acknowledged = self.acks.header();
                self.checkpoint_at_ns = super::engine_loop::now_ns();
                tracing::debug!(seconds = t0.elapsed().as_secs_f64(), "Checkpoint written.");
            }
            Err(e) => tracing::error!(error = %e, "Cannot write a checkpoint; the journal goes on."),
        }
    }

    /// Whether there is a state directory.
    pub(super) fn stored(&self) -> bool {
        self.store.is_some()
    }

    /// The journal cannot be written (a full disk).
    pub(super) fn failing(&self) -> bool {
        self.failing
    }

    /// The acknowledgements snapshots carry.
    pub(super) fn acknowledged(&self) -> [FrontendAck; MAX_FRONTENDS] {
        self.acknowledged
    }

    /// When the last checkpoint was written (ns since the UNIX epoch).
    pub(super) fn checkpoint_at_ns(&self) -> u64 {
        self.checkpoint_at_ns
    }

    /// Bytes in the journal (0 without a state directory).
    pub(super) fn journal_bytes(&self) -> u64 {
        self.store.as_ref().map_or(0, |s| s.journal_len())
    }

    /// Frontends heard from within `window`.
    pub(super) fn active(&self, window: Duration) -> usize {
        self.acks.active(window)
    }
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
        self.engine = Engine::restore(self.config.engine(), &map, tail > 0)?;
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
