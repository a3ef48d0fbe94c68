//! [`Embedded`]: slamd in this process, no daemon.

use crate::publish::{ClientError, Publish};
use slamd::config::Config;
use slamd::engine::{Engine, EnginePose, Snapshot, UpdateReport};
use slamd_types::{EdgeInput, FixInput, KeyframeId, Pose2};

/// The engine behind the [`Publish`] API, in this process, for graphs of
/// `P`'s dimension ([`Pose2`], the default, or
/// [`Pose3`](slamd_types::Pose3)).
///
/// ```
/// use slamd_client::{Config, EdgeInput, EdgeKind, Embedded, Information, Pose2, Publish};
///
/// let mut slam = Embedded::new(&Config::default());
/// let step = Pose2::new(1.0, 0.0, std::f64::consts::FRAC_PI_2);
/// for id in 0..4u64 {
///     slam.add_keyframe(id, 0, None).unwrap();
///     if id > 0 {
///         slam.add_edge(&EdgeInput::new(id - 1, id, step, Information::identity(), EdgeKind::Odometry)).unwrap();
///     }
///     slam.flush().unwrap();
/// }
/// slam.add_edge(&EdgeInput::new(3, 0, step, Information::identity(), EdgeKind::LoopClosure)).unwrap();
/// slam.flush().unwrap();
/// let snap = slam.snapshot();
/// assert_eq!(snap.len(), 4);
/// assert!(snap.chi2 < 1e-12);
/// // an edge to a keyframe that does not exist is refused at once
/// let bad = EdgeInput::new(3, 99, step, Information::identity(), EdgeKind::LoopClosure);
/// assert!(slam.add_edge(&bad).is_err());
/// ```
pub struct Embedded<P: EnginePose = Pose2> {
    engine: Engine<P>,
}

impl<P: EnginePose> Embedded<P> {
    /// An engine with `config.engine`.
    pub fn new(config: &Config) -> Self {
        Self {
            engine: Engine::create(config.engine()),
        }
    }

    /// The current estimate.
    pub fn snapshot(&self) -> Snapshot<'_, P> {
        self.engine.snapshot()
    }

    /// Updates and returns what changed (what [`Publish::flush`] does).
    pub fn update(&mut self) -> UpdateReport {
        self.engine.update()
    }

    /// The engine itself, for reweights, re-solves and statistics.
    pub fn engine(&mut self) -> &mut Engine<P> {
        &mut self.engine
    }
}

impl<P: EnginePose> Publish<P> for Embedded<P> {
    fn add_keyframe(
        &mut self,
        id: KeyframeId,
        timestamp_ns: u64,
        guess: Option<P>,
    ) -> Result<(), ClientError> {
        self.engine.add_keyframe_at(id, guess, timestamp_ns)?;
        Ok(())
    }

    fn add_edge(&mut self, edge: &EdgeInput<P>) -> Result<(), ClientError> {
        self.engine.add_edge(*edge)?;
        Ok(())
    }

    fn add_gps(&mut self, fix: &FixInput) -> Result<(), ClientError> {
        self.engine.add_gps(*fix)?;
        Ok(())
    }

    fn flush(&mut self) -> Result<(), ClientError> {
        self.engine.update();
        Ok(())
    }
}
