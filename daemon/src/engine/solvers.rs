//! [`Solvers`]: the incremental systems behind the estimate, behind one
//! seam.
//!
//! The published estimate comes from the Gauss–Newton system
//! ([`GaussNewton`], the default source) or from the exact two-stage
//! linear system ([`LinearStages`], selectable: `snapshot = "linear"`, or
//! kept beside the other with `linear_stages`). With the linear source a
//! keyframe's pose is its two-stage pose carried by its correction to the
//! last polish, `S_k = O_k ∘ L_k` with `O_k = X*_k ∘ L0_k⁻¹`. Every choice
//! between the two is made here, nowhere else in the engine.

use super::gauss_newton::GaussNewton;
use super::pose::{EnginePose, Stages};
use super::report::FactorWork;
use super::{EngineConfig, SnapshotSource};
use crate::geometry::Pose2;
use crate::graph::{Edge, PoseGraph};
use crate::nonlinear::PositionPrior;
use crate::sparse::dynamic::UpdateError;
use crate::sparse::FactorError;

/// The Gauss–Newton and two-stage systems, whichever are kept.
#[derive(Clone, Debug)]
pub struct Solvers<P: EnginePose = Pose2> {
    source: SnapshotSource,
    gn: Option<GaussNewton<P>>,
    linear: Option<P::Stages>,
    /// Per keyframe, the rigid correction from the two-stage pose to the
    /// published one (linear source).
    offset: Vec<P>,
}

impl<P: EnginePose> Solvers<P> {
    /// The Gauss–Newton system's linearisation point, if it is kept.
    pub fn linearisation(&self) -> Option<&[P]> {
        self.gn.as_ref().map(|g| g.linearisation())
    }

    /// Empty systems as `config` selects.
    pub fn new(config: &EngineConfig) -> Self {
        let source = config.snapshot;
        let linear = config.linear_stages || source == SnapshotSource::Linear;
        Self {
            source,
            gn: (source == SnapshotSource::GaussNewton).then(|| GaussNewton::new(P::IDENTITY)),
            linear: linear.then(P::Stages::create).flatten(),
            offset: Vec::new(),
        }
    }

    /// Fresh systems over the `active` edges (index, weight) and `priors`
    /// of `graph`, linearised at `lin`, eliminated in `order`; returns
    /// them with the estimate they give.
    pub fn build(
        config: &EngineConfig,
        graph: &PoseGraph<P>,
        joined: &[bool],
        active: &[(usize, f64)],
        priors: &[PositionPrior<P>],
        lin: Vec<P>,
        order: &[usize],
    ) -> Result<(Self, Vec<P>), FactorError> {
        let source = config.snapshot;
        let gn = match source {
            SnapshotSource::GaussNewton => {
                Some(GaussNewton::build(graph, active, priors, lin.clone(), order)?)
            }
            SnapshotSource::Linear => None,
        };
        let linear = if config.linear_stages || source == SnapshotSource::Linear {
            Some(P::Stages::build(graph, active, order)?)
        } else {
            None
        };
        // the correction from each two-stage pose to its polished pose
        let offset: Vec<P> = (0..graph.len())
            .map(|k| match &linear {
                Some(l) if joined[k] => lin[k].compose(&l.pose(k).inverse()),
                _ => lin[0],
            })
            .collect();
        let estimate = match &gn {
            Some(g) => g.estimate().to_vec(),
            None => lin,
        };
        let solvers = Self {
            source,
            gn,
            linear,
            offset,
        };
        Ok((solvers, estimate))
    }

    /// A new keyframe slot `k` whose gauge pose is `gauge` (keyframe 0
    /// fixes the Gauss–Newton gauge there); the two-stage solution keeps
    /// its gauge at the origin.
    pub fn push_keyframe(&mut self, k: usize, gauge: P) {
        self.offset.push(gauge);
        if k == 0 {
            if let Some(gn) = &mut self.gn {
                *gn = GaussNewton::new(gauge);
            }
        }
    }

    /// Keyframe `k` joins through `anchor`, at `guess`: a new keyframe
    /// carries its anchor's correction, so the new part of the map is the
    /// two-stage solution's, moved rigidly.
    pub fn join(&mut self, k: usize, anchor: usize, guess: P) {
        self.offset[k] = self.offset[anchor];
        if let Some(gn) = &mut self.gn {
            gn.add_keyframe(k, guess);
        }
        if let Some(l) = &mut self.linear {
            l.add_keyframe(k);
        }
    }

    /// Adds `delta` times edge `e`'s terms to every system.
    pub fn apply_edge(&mut self, e: usize, edge: &Edge<P>, delta: f64) -> Result<(), UpdateError> {
        if let Some(gn) = &mut self.gn {
            gn.apply_edge(edge, delta)?;
        }
        if let Some(l) = &mut self.linear {
            l.apply_edge(e, edge, delta)?;
        }
        Ok(())
    }

    /// Adds a GPS prior to the Gauss–Newton system, when kept (the
    /// two-stage system takes no priors).
    pub fn apply_prior(&mut self, prior: &PositionPrior<P>) -> Result<(), UpdateError> {
        match &mut self.gn {
            Some(gn) => gn.apply_prior(prior),
            None => Ok(()),
        }
    }

    /// Whether a Gauss–Newton system is kept (priors and the innovation
    /// test need it).
    pub fn has_gauss_newton(&self) -> bool {
        self.gn.is_some()
    }

    /// The Gauss–Newton system, when kept.
    pub fn gauss_newton(&mut self) -> Option<&mut GaussNewton<P>> {
        self.gn.as_mut()
    }

    /// Solves the source's system, writing the keyframes that moved to
    /// `changed` and their new poses into `estimate`.
    pub fn solve(
        &mut self,
        graph: &PoseGraph<P>,
        threshold: f64,
        changed: &mut Vec<usize>,
        estimate: &mut [P],
    ) -> Result<(), UpdateError> {
        match self.source {
            SnapshotSource::GaussNewton => {
                let gn = self.gn.as_mut().expect("Gauss–Newton source");
                changed.extend_from_slice(gn.solve(threshold)?);
                for &k in changed.iter() {
                    estimate[k] = gn.estimate()[k];
                }
            }
            SnapshotSource::Linear => {
                let l = self.linear.as_mut().expect("linear source");
                changed.extend_from_slice(l.solve(graph, threshold));
                for &k in changed.iter() {
                    estimate[k] = self.offset[k].compose(&l.pose(k));
                }
            }
        }
        Ok(())
    }

    /// χ² the Gauss–Newton model predicts for the current estimate.
    pub fn predicted_chi2(&self) -> Option<f64> {
        self.gn.as_ref().map(|g| g.predicted_chi2())
    }

    /// What the Gauss–Newton factor's update walks and back-substitutions
    /// have swept so far (zero without one).
    pub fn work(&self) -> FactorWork {
        self.gn.as_ref().map_or(FactorWork::default(), |g| FactorWork {
            walked: g.factor().walk_stats().entries,
            solved: g.solve_stats().entries,
        })
    }

    /// Stored entries of the factor behind the published estimate.
    pub fn factor_nnz(&self) -> usize {
        match (&self.gn, &self.linear) {
            (Some(gn), _) => gn.factor_nnz(),
            (None, Some(l)) => l.factor_nnz(),
            (None, None) => 0,
        }
    }

    /// The exact two-stage solution, when kept.
    pub fn linear_solution(&mut self, graph: &PoseGraph<P>) -> Option<Vec<P>> {
        self.linear.as_mut().map(|l| l.solve_exact(graph))
    }
}
