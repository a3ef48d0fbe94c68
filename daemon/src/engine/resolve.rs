//! The background re-solve: polish, fresh ordering, refactorisation, then
//! catching up with what arrived meanwhile.
//!
//! The foreground hands over a copy of the [`Model`] and the current
//! estimate, and from then on forwards every [`Op`] it applies. The worker
//! builds a fresh [`State`], replays the forwarded ops until none is left,
//! and returns the state with the sequence number of the last op it
//! applied; the foreground replays the few that came after and swaps.

use super::state::{Model, Op, Polish, State};
use super::EngineConfig;
use crate::geometry::Pose2;
use crate::sparse::FactorError;
use crossbeam::channel::{self, Receiver, Sender};
use std::thread::JoinHandle;
use std::time::Instant;

/// What a finished re-solve hands back.
pub struct Outcome {
    /// The fresh state, caught up to `last_seq`.
    pub state: Result<State, FactorError>,
    /// The last forwarded op it applied, if any.
    pub last_seq: Option<u64>,
    /// Wall time of the re-solve.
    pub seconds: f64,
}

/// A running re-solve.
pub struct Job {
    ops: Sender<(u64, Op)>,
    done: Receiver<Outcome>,
    handle: Option<JoinHandle<()>>,
}

impl Job {
    /// Starts a re-solve of `model` from `estimate` on a new thread.
    pub fn spawn(model: Model, estimate: Vec<Pose2>, config: EngineConfig) -> Job {
        let (ops, ops_rx) = channel::unbounded();
        let (done_tx, done) = channel::bounded(1);
        let handle = std::thread::Builder::new()
            .name("slamd-resolve".into())
            .spawn(move || {
                // the caller may be pinned to one core; a re-solve belongs on
                // whichever core is free
                crate::affinity::unpin_current_thread();
                let outcome = run(model, &estimate, &config, &ops_rx);
                let _ = done_tx.send(outcome);
            })
            .expect("spawn the re-solve thread");
        Job {
            ops,
            done,
            handle: Some(handle),
        }
    }

    /// Forwards an op the foreground applied.
    pub fn forward(&self, seq: u64, op: Op) {
        let _ = self.ops.send((seq, op));
    }

    /// The outcome, if the re-solve has finished.
    pub fn try_finish(&mut self) -> Option<Outcome> {
        let outcome = self.done.try_recv().ok()?;
        self.join();
        Some(outcome)
    }

    /// Lets the re-solve run out on its own and drops its outcome (the
    /// thread is detached; the closed channel ends its catching up).
    pub fn abandon(mut self) {
        self.handle.take();
    }

    /// Waits for the outcome.
    pub fn finish(mut self) -> Option<Outcome> {
        let outcome = self.done.recv().ok();
        self.join();
        outcome
    }

    fn join(&mut self) {
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Builds the fresh state and catches up (also used inline, with no ops).
pub fn run(model: Model, estimate: &[Pose2], config: &EngineConfig, ops: &Receiver<(u64, Op)>) -> Outcome {
    let start = Instant::now();
    let _span = tracing::debug_span!("resolve", keyframes = model.graph.len()).entered();
    let state = State::rebuild(model, estimate, Polish::Full, config);
    let mut last_seq = None;
    let state = state.map(|mut s| {
        // ops were validated by the foreground; a numeric failure here only
        // costs this re-solve its catch-up accuracy
        while let Ok((seq, op)) = ops.try_recv() {
            let _ = s.apply(&op);
            last_seq = Some(seq);
        }
        // a numeric failure here leaves the state stale; the foreground
        // will notice when its own solve fails and rebuild
        let _ = s.solve(config.wildfire_threshold);
        s
    });
    let seconds = start.elapsed().as_secs_f64();
    tracing::debug!(seconds, "Re-solve finished.");
    Outcome {
        state,
        last_seq,
        seconds,
    }
}
