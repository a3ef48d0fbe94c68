//! [`Background`]: the re-solve or refresh running on its own thread, and
//! what the foreground owes it.
//!
//! While a job runs, every op the foreground applies is forwarded to it
//! and kept in a log, numbered; after each update the foreground forwards
//! its estimate of the keyframes that joined, as catch-up hints. When the
//! job finishes, [`catch_up`] replays the ops it had not applied onto its
//! fresh state, which then replaces the foreground's.

use super::pose::EnginePose;
use super::report::FactorWork;
use super::resolve::{self, Job, Outcome};
use super::state::{Op, State};
use super::{EngineConfig, Polish};
use crate::geometry::Pose2;

/// The ops applied while a job ran, numbered.
pub type Log<P> = Vec<(u64, Op<P>)>;
use crate::sparse::FactorError;
use std::time::Instant;

/// The running job, if any, and the ops applied since it started.
pub struct Background<P: EnginePose = Pose2> {
    job: Option<Job<P>>,
    /// Called when a job's outcome is ready.
    waker: Option<resolve::Waker>,
    log: Log<P>,
    /// The next op's number.
    seq: u64,
    /// Keyframes below this index are known to the running job's hints
    /// (handed over, or forwarded after an update)...
    hinted: usize,
    /// ...but for these, which had not joined yet (a keyframe whose edges
    /// come in a later batch): their hints go once they join.
    unhinted: Vec<usize>,
}

impl<P: EnginePose> Default for Background<P> {
    fn default() -> Self {
        Self {
            job: None,
            waker: None,
            log: Vec::new(),
            seq: 0,
            hinted: 0,
            unhinted: Vec::new(),
        }
    }
}

impl<P: EnginePose> Background<P> {
    /// Calls `waker` (on the job's thread) whenever a job's outcome is
    /// ready.
    pub fn wake_with(&mut self, waker: resolve::Waker) {
        self.waker = Some(waker);
    }

    /// Whether a job runs.
    pub fn running(&self) -> bool {
        self.job.is_some()
    }

    /// Numbers `op`, applied in the foreground, and forwards it to the
    /// running job.
    pub fn record(&mut self, op: Op<P>) {
        if let Some(job) = &self.job {
            job.forward(self.seq, op.clone());
            self.log.push((self.seq, op));
        }
        self.seq += 1;
    }

    /// Forwards `state`'s estimates of the keyframes that joined since the
    /// last call to the running job.
    pub fn forward_estimates(&mut self, state: &State<P>) {
        let Some(job) = &self.job else {
            return;
        };
        let (model, estimate) = (&state.model, state.estimate());
        let n = model.graph.len();
        self.unhinted.extend(self.hinted..n);
        self.unhinted.retain(|&k| {
            let joined = model.joined(k);
            if joined {
                job.hint(k, estimate[k]);
            }
            !joined
        });
        self.hinted = n;
    }

    /// Starts a job on `state`'s model, with the outlier filter's
    /// `decided` switches set in it, and its estimate.
    pub fn start(
        &mut self,
        state: &State<P>,
        config: &EngineConfig,
        polish: Polish,
        decided: &[(usize, f64)],
    ) {
        let (mut model, estimate) = (state.model().clone(), state.estimate().to_vec());
        for &(e, switch) in decided {
            if let Some(state) = model.edges.get_mut(e) {
                state.switch = switch;
            }
        }
        self.log.clear();
        self.hinted = state.model.graph.len();
        // without its hint such a keyframe would join the job's catch-up at
        // its input guess (dead-reckoned by the frontend, metres off late in
        // a long run) and bend the map there
        self.unhinted = (0..self.hinted).filter(|&k| !state.model.joined(k)).collect();
        let waker = self.waker.clone();
        self.job = Some(Job::spawn(model, estimate, config.clone(), polish, waker));
    }

    /// The finished job's outcome and the ops applied since it started.
    pub fn poll(&mut self) -> Option<(Outcome<P>, Log<P>)> {
        let outcome = self.job.as_mut()?.try_finish()?;
        self.job = None;
        Some((outcome, std::mem::take(&mut self.log)))
    }

    /// Abandons the running job, if any: it stops at its next check and
    /// its outcome is dropped.
    pub fn abandon(&mut self) {
        if let Some(job) = self.job.take() {
            job.abandon();
            self.log.clear();
        }
    }
}

impl<P: EnginePose> Drop for Background<P> {
    fn drop(&mut self) {
        if let Some(job) = self.job.take() {
            job.stop();
        }
    }
}

/// Runs a job inline on `state`'s model and estimate (no background
/// thread).
pub fn run_inline<P: EnginePose>(
    state: &State<P>,
    config: &EngineConfig,
    polish: Polish,
) -> Option<Outcome<P>> {
    let (model, estimate) = (state.model().clone(), state.estimate());
    let (_tx, rx) = crossbeam::channel::unbounded();
    let never = std::sync::atomic::AtomicBool::new(false);
    resolve::run(model, estimate, config, polish, &rx, &never)
}

/// The job's fresh `state`, which applied the ops up to `last_seq`,
/// caught up with the rest of the `log`: they join where `foreground`'s
/// solves put them. Returns it with its work counters as they stood before
/// the catch-up (the catch-up is this thread's work), or `None` when the
/// job failed or an op cannot be replayed (the foreground keeps its state).
pub fn catch_up<P: EnginePose>(
    state: Result<State<P>, FactorError>,
    last_seq: Option<u64>,
    log: Log<P>,
    foreground: &State<P>,
    config: &EngineConfig,
) -> Option<(State<P>, FactorWork)> {
    let Ok(mut state) = state else {
        tracing::warn!("Re-solve failed; keeping the current factor.");
        return None;
    };
    let base = state.work();
    state.set_hints(
        foreground.estimate(),
        foreground.model.keyframes.iter().map(|k| k.joined),
    );
    let (caught_up, mut replayed) = (Instant::now(), 0);
    for (seq, op) in log {
        if last_seq.is_none_or(|last| seq > last) {
            replayed += 1;
            if let Err(e) = state.replay(&op, config.wildfire_threshold) {
                tracing::warn!(error = %e, seq, ?op, "Re-solve cannot replay an op; discarded.");
                return None;
            }
        }
    }
    if let Err(e) = state.join_new() {
        tracing::warn!(error = %e, "Re-solve cannot connect the replayed edges; discarded.");
        return None;
    }
    state.clear_hints();
    tracing::debug!(
        replayed,
        catch_up_seconds = caught_up.elapsed().as_secs_f64(),
        "Re-solve caught up."
    );
    Some((state, base))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::state::tests::{keyframe, odometry};

    /// A keyframe whose edges come after it has not joined when a job
    /// starts, or when the estimates after its update are forwarded; its
    /// hint goes once it joins (without one it would join the job's
    /// catch-up at its input guess).
    #[test]
    fn a_keyframe_that_joins_late_is_hinted_once_it_joins() {
        let config = EngineConfig::default();
        let step = Pose2::new(1.0, 0.0, 0.0);
        let mut state = State::new(&config);
        for k in 0..3 {
            state.replay(&keyframe(k), 0.0).unwrap();
            if k > 0 {
                state.replay(&odometry(k - 1, k, step), 0.0).unwrap();
            }
        }
        state.replay(&keyframe(3), 0.0).unwrap();
        state.solve(0.0).unwrap();
        let mut background = Background::default();
        background.start(&state, &config, Polish::None, &[]);
        assert_eq!(background.unhinted, vec![3]);

        state.replay(&keyframe(4), 0.0).unwrap();
        state.solve(0.0).unwrap();
        background.forward_estimates(&state);
        assert_eq!(background.unhinted, vec![3, 4], "neither has joined");

        state.replay(&odometry(2, 3, step), 0.0).unwrap();
        state.solve(0.0).unwrap();
        background.forward_estimates(&state);
        assert_eq!(background.unhinted, vec![4], "3 joined and was hinted");

        state.replay(&odometry(3, 4, step), 0.0).unwrap();
        state.solve(0.0).unwrap();
        background.forward_estimates(&state);
        assert!(background.unhinted.is_empty());
    }
}
