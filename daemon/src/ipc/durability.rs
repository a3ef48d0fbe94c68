//! [`Durability`]: what makes the daemon's input durable. Which messages
//! each frontend has had taken, the state directory's journal and
//! checkpoints, and the acknowledgements snapshots carry.
//!
//! Order of a batch: the messages are admitted and their records
//! buffered; [`Durability::commit`] writes the journal (and fsyncs it as
//! `state.sync` says); only then does the snapshot go out with the
//! acknowledgements. A commit that fails (a full disk) leaves the
//! acknowledgements where they were and is tried again at every tick;
//! the records stay buffered, so nothing taken is lost while the daemon
//! lives.

use super::acks::Acks;
use crate::engine::EnginePose;
use crate::store::{MapFile, Record, StateDir};
use slamd_protocol::{FrontendAck, MAX_FRONTENDS};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// What makes the daemon's input durable: which messages each frontend
/// has had taken, the state directory's journal and checkpoints, and the
/// acknowledgements snapshots carry, which never run ahead of the disk.
pub(super) struct Durability {
    /// What each frontend has had taken.
    pub(super) acks: Acks,
    /// The acknowledgements snapshots carry: of what the journal holds
    /// (without a state directory, of what was taken).
    pub(super) acknowledged: [FrontendAck; MAX_FRONTENDS],
    /// The state directory, if any.
    pub(super) store: Option<StateDir>,
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
                self.checkpoint_at_ns = now_ns();
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

/// Nanoseconds since the UNIX epoch.
pub(super) fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}
