//! [`DriftRun`]: telling a drifted map from wrong loop closures at arrival.
//!
//! A loop closure `(i, j)` enters with the switch its error has under the
//! current estimate. After a long loop the estimate of `j` carries drift,
//! so the first true loop closure is switched off, and so is every one
//! after it: the keyframes that follow are dead-reckoned from `j`, and the
//! off switches weigh nothing, so no update corrects them: snapshots stray
//! orders of magnitude from their prefix's optimum until a re-solve.
//!
//! What sets such a run apart is agreement. Each rejected loop closure
//! implies a pose `x̂_j = x_i ∘ Z_ij` and so a correction of the map,
//! `C = x̂_j ∘ x_j⁻¹`; a rigidly drifted chain gives the same `C` for every
//! loop closure along it. Two loop closures agree when the previous one's
//! correction predicts this one's pose, `C_prev ∘ x_j`, within the arrival
//! gate (`eᵀ Ω e ≤ Φ` with this edge's information). Random wrong loop
//! closures disagree; Vertigo's grouped ones agree in groups of ten. A run
//! of agreeing rejections longer than any such group means the map
//! drifted, and the engine re-solves at once. A shorter run may enter at
//! once when the map holds its ends loosely enough (the engine's arrival
//! gate, `arrival_covariance`); the run names its members for that.

use crate::geometry::Pose2;
use crate::graph::{Edge, EdgeCost};

/// Keyframes a run may skip between two of its loop closures.
pub const RUN_GAP: usize = 50;

/// The current run of agreeing rejected loop closures.
#[derive(Clone, Debug)]
pub struct DriftRun<P = Pose2> {
    /// The newer keyframe and the correction of the run's last member.
    last: Option<(usize, P)>,
    /// The run's loop closures (edge index, and whether the caller vouched
    /// for it), oldest first.
    members: Vec<(usize, bool)>,
}

impl<P> Default for DriftRun<P> {
    fn default() -> Self {
        Self {
            last: None,
            members: Vec::new(),
        }
    }
}

impl<P: EdgeCost> DriftRun<P> {
    /// Records that loop closure `e`, `edge` (between keyframes at `xi`,
    /// `xj`), was switched off on arrival, and whether the caller `vouched`
    /// for it. Returns the length of the run it now belongs to.
    pub fn rejected(&mut self, e: usize, vouched: bool, edge: &Edge<P>, xi: &P, xj: &P, phi: f64) -> usize {
        let newer = edge.from.max(edge.to);
        let implied = xi.compose(&edge.measurement);
        let correction = implied.compose(&xj.inverse());
        let agrees = self.last.is_some_and(|(k, previous)| {
            let e = previous.compose(xj).between(&implied).vector();
            newer.abs_diff(k) <= RUN_GAP && P::mahalanobis(&edge.information, &e) <= phi
        });
        if !agrees {
            self.members.clear();
        }
        self.members.push((e, vouched));
        self.last = Some((newer, correction));
        self.members.len()
    }

    /// How many of the run's loop closures were vouched for.
    pub fn vouched(&self) -> usize {
        self.members.iter().filter(|m| m.1).count()
    }

    /// The run's loop closures that were vouched for, oldest first; the
    /// run ends.
    pub fn take_vouched(&mut self) -> Vec<usize> {
        self.last = None;
        let members = std::mem::take(&mut self.members);
        members.into_iter().filter(|m| m.1).map(|m| m.0).collect()
    }

    /// Ends the run (the map was corrected).
    pub fn clear(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge(from: usize, to: usize, z: Pose2) -> Edge {
        Edge::unit_loop_closure(from, to, z)
    }

    #[test]
    fn a_drifted_chain_gives_agreeing_rejections() {
        // the true map: keyframe k at (k, 0); the estimate of the chain from
        // keyframe 100 on is rotated by 0.3 rad about the origin and moved
        let drift = Pose2::new(2.0, -1.0, 0.3);
        let truth = |k: usize| Pose2::new(k as f64, 0.0, 0.0);
        let mut run = DriftRun::default();
        for (n, j) in (100..125).enumerate() {
            let i = j - 100;
            let z = truth(i).between(&truth(j));
            let xj = drift.compose(&truth(j));
            assert_eq!(
                run.rejected(n, n % 2 == 0, &edge(i, j, z), &truth(i), &xj, 16.27),
                n + 1
            );
        }
        // the run names the members vouched for, and taking them ends it
        assert_eq!(run.vouched(), 13);
        assert_eq!(run.take_vouched(), (0..25).step_by(2).collect::<Vec<_>>());
        let z = truth(0).between(&truth(125));
        let xj = drift.compose(&truth(125));
        assert_eq!(run.rejected(25, true, &edge(0, 125, z), &truth(0), &xj, 16.27), 1);
        assert_eq!(run.vouched(), 1);
    }

    #[test]
    fn random_wrong_loop_closures_disagree() {
        let truth = |k: usize| Pose2::new(k as f64, 0.0, 0.0);
        let mut run = DriftRun::default();
        // each one claims a different, large offset
        for (n, j) in (100..110).enumerate() {
            let z = Pose2::new(5.0 * n as f64, -3.0 * n as f64, 0.4 * n as f64);
            let len = run.rejected(n, true, &edge(j - 50, j, z), &truth(j - 50), &truth(j), 16.27);
            assert_eq!(len, 1, "rejection {n}");
        }
    }

    #[test]
    fn a_gap_longer_than_run_gap_starts_a_new_run() {
        let truth = |k: usize| Pose2::new(k as f64, 0.0, 0.0);
        let drift = Pose2::new(1.0, 1.0, 0.1);
        let mut run = DriftRun::default();
        for (j, expected) in [(100, 1), (101, 2), (101 + RUN_GAP + 1, 1)] {
            let z = truth(0).between(&truth(j));
            let xj = drift.compose(&truth(j));
            assert_eq!(
                run.rejected(j, false, &edge(0, j, z), &truth(0), &xj, 16.27),
                expected
            );
        }
        run.clear();
        let z = truth(0).between(&truth(300));
        assert_eq!(
            run.rejected(300, false, &edge(0, 300, z), &truth(0), &truth(300), 16.27),
            1
        );
    }
}
