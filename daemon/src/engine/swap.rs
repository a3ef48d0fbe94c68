//! How the engine's state is replaced: re-solves inline and on the
//! background thread, refreshes, reorderings, and the swap that makes a
//! fresh state current.

use super::background;
use super::op::Polish;
use super::pose::EnginePose;
use super::rebuild;
use super::report::FactorWork;
use super::resolve;
use super::state::State;
use super::Engine;

impl<P: EnginePose> Engine<P> {
    /// A full re-solve here. A running background re-solve is abandoned:
    /// this one covers everything it does, and more; swapped in
    /// afterwards, the older one would leave the newest edges unpolished
    /// with no re-solve due.
    pub(super) fn resolve_inline(&mut self, polish: Polish) -> usize {
        self.resolve_inline_from(polish, &[])
    }

    /// [`Self::resolve_inline`] starting from `start` where it has a pose
    /// (else from the estimate).
    pub(super) fn resolve_inline_from(&mut self, polish: Polish, start: &[P]) -> usize {
        self.background.abandon();
        // what the swapped-in state replayed is not connected yet, and a rebuild
        // polishes only connected edges: connect them first
        self.solve();
        // the rebuild takes the judge's deferred switches in
        let deferred: Vec<(usize, f64)> = self.deferred.drain().collect();
        for (e, _) in &deferred {
            self.undecided.remove(e);
        }
        if let Err(e) = self.state.set_switches_for_rebuild(&deferred) {
            tracing::error!(error = %e, "Cannot take a decision of the judge.");
        }
        self.state.start_from(start);
        self.rebuild_inline(polish);
        self.stats.resolves += 1;
        self.solve()
    }

    /// Starts a re-solve ([`Polish::Full`]) or a refresh ([`Polish::None`]),
    /// on the background thread when configured, else here.
    pub(super) fn start_job(&mut self, polish: Polish) {
        self.schedule.started(polish, &self.state);
        if self.config.background {
            let decided: Vec<(usize, f64)> = self.deferred.iter().map(|(&e, &s)| (e, s)).collect();
            self.background.start(&self.state, &self.config, polish, &decided);
        } else if let Some(outcome) = background::run_inline(&self.state, &self.config, polish) {
            self.swap_in(outcome, Vec::new());
        }
    }

    /// Swaps in the background job's state if it finished.
    pub(super) fn poll_background(&mut self) -> bool {
        match self.background.poll() {
            Some((outcome, log)) => self.swap_in(outcome, log),
            None => false,
        }
    }

    /// Catches the job's state up with the ops in `log` and makes it
    /// current.
    pub(super) fn swap_in(&mut self, outcome: resolve::Outcome<P>, log: background::Log<P>) -> bool {
        let resolve::Outcome {
            state,
            last_seq,
            seconds,
            polish,
        } = outcome;
        let Some((state, base)) = background::catch_up(state, last_seq, log, &self.state, &self.config)
        else {
            return false;
        };
        self.replace_state(state, base);
        let edges = &self.state.model.edges;
        let undecided = &mut self.undecided;
        self.deferred.retain(|&e, s| {
            let waits = edges.get(e).is_some_and(|state| state.switch != *s);
            if !waits {
                undecided.remove(&e);
            }
            waits
        });
        self.schedule.fresh(&self.state);
        if polish == Polish::None {
            self.stats.refreshes += 1;
        } else {
            self.stats.resolves += 1;
            self.stats.resolve_seconds += seconds;
        }
        tracing::debug!(
            keyframes = self.keyframe_count(),
            seconds,
            chi2 = self.state.chi2(),
            "Re-solve swapped in."
        );
        true
    }

    /// Refactorises with a fresh ordering at the same linearisation
    /// point ([`State::reordered`]), inline.
    pub(super) fn reorder_inline(&mut self) {
        match self.state.reordered(&self.config) {
            Ok(state) => {
                self.stats.reorders += 1;
                let base = state.work();
                self.replace_state(state, base);
                self.schedule.fresh(&self.state);
            }
            Err(e) => tracing::warn!(error = %e, "Reordering failed; keeping the current factor."),
        }
    }

    /// Rebuilds the state here, polished as `polish` says. Only a polish
    /// restarts the re-solve schedule and the fill baseline; a
    /// relinearisation or a recovery ([`Polish::None`]) leaves them.
    pub(super) fn rebuild_inline(&mut self, polish: Polish) {
        let (model, start) = (self.state.model().clone(), self.state.estimate());
        match rebuild::rebuild(model, start, polish, &self.config) {
            Ok(state) => {
                let base = state.work();
                self.replace_state(state, base);
                if polish != Polish::None {
                    self.schedule.fresh(&self.state);
                    self.schedule.polished(&self.state);
                }
            }
            Err(e) => tracing::error!(error = %e, "Refactorisation failed; the estimate is stale."),
        }
    }

    /// Makes `state` current; its work counters stood at `base` when this
    /// thread's work on it began.
    pub(super) fn replace_state(&mut self, state: State<P>, base: FactorWork) {
        self.work_done += self.state.work() - self.work_base;
        self.work_base = base;
        let mut state = state;
        state.changed_all();
        retire(std::mem::replace(&mut self.state, state));
    }
}

/// Drops a replaced state on a thread of its own: freeing a factor's
/// tens of thousands of columns is work the foreground need not wait for.
pub(super) fn retire<P: EnginePose>(old: State<P>) {
    // without a thread (resource limits) the closure, and the state with
    // it, is dropped here
    let _ = std::thread::Builder::new()
        .name("slamd-retire".into())
        .spawn(move || {
            // spawned by the engine thread, it would share a pinned core
            crate::affinity::run_in_background();
            drop(old)
        });
}
