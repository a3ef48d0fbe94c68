//! The background re-solve: polish, fresh ordering, refactorisation, then
//! catching up with what arrived meanwhile. Without the polish
//! ([`Polish::None`]) it is a refresh: every edge relinearised at the
//! estimate and factorised exactly, one Gauss–Newton iteration.
//!
//! The foreground hands over a copy of the [`Model`] and the current
//! estimate, and from then on forwards every [`Op`] it applies and, after
//! each update, its estimate of the keyframes that joined ([`Forward`]).
//! The worker builds a fresh [`State`], replays the forwarded ops with
//! those estimates as hints (so new keyframes join where the foreground
//! put them, and one back-substitution ends the catch-up instead of one
//! per keyframe), and returns the state with the sequence number of the
//! last op it applied; the foreground replays the few that came after and
//! swaps.

use super::pose::EnginePose;
use super::rebuild;
use super::state::{Model, Op, Polish, State};
use super::EngineConfig;
use crate::geometry::Pose2;
use crate::sparse::FactorError;
use crossbeam::channel::{self, Receiver, Sender};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;

/// Called on a re-solve's thread when its outcome is ready (the daemon
/// wakes its engine loop with it, so the outcome swaps in at once).
pub type Waker = Arc<dyn Fn() + Send + Sync>;

/// What a finished re-solve hands back.
pub struct Outcome<P: EnginePose = Pose2> {
    /// The fresh state, caught up to `last_seq`.
    pub state: Result<State<P>, FactorError>,
    /// The last forwarded op it applied, if any.
    pub last_seq: Option<u64>,
    /// Wall time of the re-solve.
    pub seconds: f64,
    /// How it polished ([`Polish::None`]: a refresh).
    pub polish: Polish,
}

/// What the foreground forwards to a running re-solve.
pub enum Forward<P: EnginePose = Pose2> {
    /// An op it applied, with its sequence number.
    Op(u64, Op<P>),
    /// Its estimate of a keyframe that joined, after an update.
    Estimate(usize, P),
}

/// A running re-solve.
pub struct Job<P: EnginePose = Pose2> {
    ops: Sender<Forward<P>>,
    done: Receiver<Outcome<P>>,
    handle: Option<JoinHandle<()>>,
    /// Set when nobody waits for the outcome any more.
    stop: Arc<AtomicBool>,
}

impl<P: EnginePose> Job<P> {
    /// Starts a re-solve of `model` from `estimate` on a new thread;
    /// `wake` is called there once its outcome is ready.
    pub fn spawn(
        model: Model<P>,
        estimate: Vec<P>,
        config: EngineConfig,
        polish: Polish,
        wake: Option<Waker>,
    ) -> Self {
        let (ops, ops_rx) = channel::unbounded();
        let (done_tx, done) = channel::bounded(1);
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = Arc::clone(&stop);
        let handle = std::thread::Builder::new()
            .name("slamd-resolve".into())
            .spawn(move || {
                // the daemon's engine thread may hold a reserved core; a
                // re-solve belongs on the others
                crate::affinity::run_in_background();
                if let Some(mut outcome) = run(model, &estimate, &config, polish, &ops_rx, &stopped) {
                    if !stopped.load(Ordering::Relaxed) {
                        outcome.state = outcome.state.map(|s| relinearised(s, &config));
                    }
                    if done_tx.send(outcome).is_ok() {
                        if let Some(wake) = wake {
                            wake();
                        }
                    }
                }
            })
            .expect("spawn the re-solve thread");
        Job {
            ops,
            done,
            handle: Some(handle),
            stop,
        }
    }

    /// Forwards an op the foreground applied.
    pub fn forward(&self, seq: u64, op: Op<P>) {
        let _ = self.ops.send(Forward::Op(seq, op));
    }

    /// Forwards the foreground's estimate of keyframe `k`.
    pub fn hint(&self, k: usize, pose: P) {
        let _ = self.ops.send(Forward::Estimate(k, pose));
    }

    /// The outcome, if the re-solve has finished.
    pub fn try_finish(&mut self) -> Option<Outcome<P>> {
        let outcome = self.done.try_recv().ok()?;
        self.join();
        Some(outcome)
    }

    /// Stops the re-solve where it is and drops its outcome without
    /// waiting (as dropping the job does): its polish ends at the next
    /// iteration, it skips the factorisation, and the closed channel ends
    /// its catching up, so an abandoned re-solve frees its core at once.
    pub fn abandon(self) {}

    /// Stops the re-solve as [`Self::abandon`] does and waits for its
    /// thread to end.
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.join();
    }

    fn join(&mut self) {
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

impl<P: EnginePose> Drop for Job<P> {
    /// Stops a re-solve nobody will take (the thread is detached).
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Relinearisations a re-solve may make before handing over.
const RELINEARISATIONS: usize = 2;

/// `state`, relinearised at its estimate and refactorised while its χ²
/// sits past the foreground's relinearisation check (at most
/// [`RELINEARISATIONS`] times, and only while that lowers it), so that the
/// foreground does not do it inline once the state swaps in. A polish
/// leaves a long chain of keyframes whose loop closures are still pending
/// (the judge behind) one Gauss–Newton step from where the step's
/// linearisation holds: a small rotation at its base moves its far end
/// tens of metres, and the keyframes caught up meet it there.
fn relinearised<P: EnginePose>(mut state: State<P>, config: &EngineConfig) -> State<P> {
    for _ in 0..RELINEARISATIONS {
        if !super::off_model(&state, config.relinearise_ratio, super::RELINEARISE_SLACK) {
            break;
        }
        let fresh = rebuild::rebuild(state.model().clone(), state.estimate(), Polish::None, config);
        let Ok(mut fresh) = fresh else { break };
        if fresh.solve(config.wildfire_threshold).is_err() || fresh.chi2() >= state.chi2() {
            break;
        }
        tracing::debug!(
            chi2 = fresh.chi2(),
            predicted = fresh.predicted_chi2(),
            "Re-solve relinearised before handing over."
        );
        state = fresh;
    }
    state
}

/// Passes over the queued ops a re-solve makes before handing over.
const CATCH_UP_PASSES: usize = 3;

/// A catch-up pass that replayed this many ops refactorises with a fresh
/// ordering before the next one ([`State::reordered`]).
const REORDER_AFTER: usize = 256;

/// Builds the fresh state and catches up (also used inline, with no ops).
/// `None` when `stop` was set before the factorisation.
pub fn run<P: EnginePose>(
    mut model: Model<P>,
    estimate: &[P],
    config: &EngineConfig,
    polish: Polish,
    ops: &Receiver<Forward<P>>,
    stop: &AtomicBool,
) -> Option<Outcome<P>> {
    let start = Instant::now();
    let _span = tracing::debug_span!("resolve", keyframes = model.graph.len(), ?polish).entered();
    let joined = model.joined_flags();
    let lin = rebuild::polish_model(&mut model, estimate, polish, config, stop);
    if stop.load(Ordering::Relaxed) {
        tracing::debug!(seconds = start.elapsed().as_secs_f64(), "Re-solve stopped.");
        return None;
    }
    let state = State::factorise(model, lin, config);
    let mut last_seq = None;
    let (built, mut replayed) = (start.elapsed().as_secs_f64(), 0);
    let state = state.map(|mut s| {
        // ops were validated by the foreground; a numeric failure here only
        // costs this re-solve its catch-up accuracy. Each pass takes what
        // is queued; the foreground replays what comes after. A replayed
        // op costs about what it cost the foreground, so chasing the queue
        // to empty need never end while input keeps coming
        s.set_hints(estimate, joined.iter().copied());
        for _ in 0..CATCH_UP_PASSES {
            let queued = ops.len();
            if queued == 0 {
                break;
            }
            let mut pass = 0;
            for forward in ops.try_iter().take(queued) {
                match forward {
                    Forward::Op(seq, op) => {
                        let _ = s.replay(&op, config.wildfire_threshold);
                        last_seq = Some(seq);
                        pass += 1;
                    }
                    Forward::Estimate(k, pose) => s.hint(k, pose),
                }
            }
            replayed += pass;
            // the keyframes a long pass appended fill the factor in for
            // every later op, here and in the foreground after the swap
            if pass >= REORDER_AFTER {
                if let Ok(fresh) = s.reordered(config) {
                    s = fresh;
                }
            }
        }
        // a numeric failure here leaves the state stale; the foreground
        // will notice when its own solve fails and rebuild
        let _ = s.solve(config.wildfire_threshold);
        s.clear_hints();
        s
    });
    let seconds = start.elapsed().as_secs_f64();
    tracing::debug!(seconds, built, replayed, "Re-solve finished.");
    Some(Outcome {
        state,
        last_seq,
        seconds,
        polish,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::state::tests::keyframe;
    use crate::engine::Op;
    use crate::synthetic::{generate, WorldParams};
    use slamd_protocol::codec::Origin;

    /// A synthetic world streamed into a state that never relinearises
    /// ends past the foreground's relinearisation check (its loop closures
    /// pulled the map far from where it was linearised). Relinearised
    /// before it is handed over, it is within the check, its χ² lower; a
    /// state within the check is handed over as it is.
    #[test]
    fn a_state_off_its_linear_model_is_relinearised_before_it_is_handed_over() {
        let config = EngineConfig::default();
        let world = generate(&WorldParams {
            poses: 1000,
            ..WorldParams::default()
        });
        let mut state = State::new(&config);
        let mut edges = (0..world.graph.edges().len()).peekable();
        for k in 0..world.graph.len() {
            state
                .replay(&keyframe(k as u64), config.wildfire_threshold)
                .unwrap();
            while let Some(e) =
                edges.next_if(|&e| world.graph.edges()[e].from.max(world.graph.edges()[e].to) <= k)
            {
                let op = Op::Edge(world.graph.edge_input(e), Origin::LOCAL);
                state.replay(&op, config.wildfire_threshold).unwrap();
            }
        }
        state.solve(config.wildfire_threshold).unwrap();
        let (ratio, slack) = (config.relinearise_ratio, super::super::RELINEARISE_SLACK);
        let off = |s: &State| super::super::off_model(s, ratio, slack);
        assert!(
            off(&state),
            "χ² {} against {}",
            state.chi2(),
            state.predicted_chi2()
        );

        let before = state.chi2();
        let handed = relinearised(state, &config);
        assert!(handed.chi2() < before, "χ² {before} → {}", handed.chi2());
        assert!(
            !off(&handed),
            "χ² {} against {}",
            handed.chi2(),
            handed.predicted_chi2()
        );

        let at = handed.chi2();
        let again = relinearised(handed, &config);
        assert_eq!(again.chi2(), at);
    }
}
