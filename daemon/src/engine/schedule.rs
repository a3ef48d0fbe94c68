//! [`Schedule`]: when the next re-solve or refresh is due.
//!
//! A re-solve (polish, fresh ordering, fresh factor) is due after
//! `resolve_every_edges` new edges, when the factor holds
//! `resolve_fill_ratio` times the entries per column it held after the
//! last re-solve (fill-in, which every update walks; a map that grows by
//! odometry alone grows its factor in proportion and is not filled), or
//! when GPS fixes call for a georeference: as soon as two are in the
//! estimate, and again whenever their number has doubled. A refresh (the
//! same without the polish) is due after `refresh_every_edges` new edges.
//! The caller checks that the background thread is free.

use super::pose::EnginePose;
use super::state::State;
use super::{EngineConfig, Polish};

/// Counters since the last re-solve and refresh.
#[derive(Clone, Debug, Default)]
pub struct Schedule {
    edges_since_resolve: usize,
    edges_since_refresh: usize,
    /// Stored entries of the factor after the last re-solve.
    nnz_after_resolve: usize,
    /// Its columns then.
    columns_after_resolve: usize,
    /// Fixes in the estimate at the last re-solve.
    fixes_at_resolve: usize,
}

impl Schedule {
    /// A new edge arrived.
    pub fn edge_added(&mut self) {
        self.edges_since_resolve += 1;
        self.edges_since_refresh += 1;
    }

    /// Whether edges arrived since the last re-solve.
    pub fn has_new_edges(&self) -> bool {
        self.edges_since_resolve > 0
    }

    /// Whether a re-solve is due for `state`.
    pub fn resolve_due<P: EnginePose>(&self, config: &EngineConfig, state: &State<P>) -> bool {
        let c = config;
        let by_count = c.resolve_every_edges > 0 && self.edges_since_resolve >= c.resolve_every_edges;
        // inline, a filled factor is refactorised (`Engine::update`): a
        // robust re-solve is a statistical decision, not a remedy for fill
        let by_fill = c.background && self.filled(config, state);
        // the count of fixes on joined keyframes is a scan, so it waits
        // until all fixes together could pass
        let due = |fixes: usize| fixes >= 2 && fixes >= 2 * self.fixes_at_resolve.max(1);
        let by_gps = due(state.model.fixes.len()) && due(state.usable_fixes());
        by_count || by_fill || by_gps
    }

    /// Whether `state`'s factor holds `resolve_fill_ratio` times the
    /// entries per column it held when it was last fresh.
    pub fn filled<P: EnginePose>(&self, config: &EngineConfig, state: &State<P>) -> bool {
        let ratio = config.resolve_fill_ratio;
        let (nnz, columns) = (state.factor_nnz() as f64, state.factor_columns().max(1) as f64);
        ratio > 0.0
            && self.nnz_after_resolve > 0
            && nnz * self.columns_after_resolve as f64 > ratio * self.nnz_after_resolve as f64 * columns
    }

    /// Whether a refresh is due (with the background thread free).
    pub fn refresh_due(&self, config: &EngineConfig) -> bool {
        let every = config.refresh_every_edges;
        config.background && every > 0 && self.edges_since_refresh >= every
    }

    /// A re-solve ([`Polish::Full`]) or a refresh ([`Polish::None`])
    /// starts from `state`.
    pub fn started<P: EnginePose>(&mut self, polish: Polish, state: &State<P>) {
        self.edges_since_refresh = 0;
        if polish != Polish::None {
            self.polished(state);
        }
    }

    /// A polished state was built inline from `state`: the re-solve
    /// schedule restarts.
    pub fn polished<P: EnginePose>(&mut self, state: &State<P>) {
        self.edges_since_resolve = 0;
        self.fixes_at_resolve = state.usable_fixes();
    }

    /// `state`, fresh from a re-solve or refresh, is current: the fill
    /// baseline is its factor.
    pub fn fresh<P: EnginePose>(&mut self, state: &State<P>) {
        self.nnz_after_resolve = state.factor_nnz();
        self.columns_after_resolve = state.factor_columns().max(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::state::tests::{keyframe, odometry};
    use crate::engine::{EdgeInput, Op};
    use crate::geometry::Pose2;
    use crate::graph::{EdgeKind, Information};
    use slamd_protocol::codec::Origin;

    /// Appends keyframes `from..to` along x by odometry, solved.
    fn extend(state: &mut State, from: u64, to: u64) {
        let step = Pose2::new(1.0, 0.0, 0.0);
        for k in from..to {
            state.replay(&keyframe(k), 0.0).unwrap();
            if k > 0 {
                state.replay(&odometry(k - 1, k, step), 0.0).unwrap();
            }
        }
        state.solve(0.0).unwrap();
    }

    /// A map five times longer by odometry alone holds about the entries
    /// per column it held: not filled. Loop closures from keyframe 1 (the
    /// gauge is no column) to every tenth fill the factor in: filled.
    #[test]
    fn growth_by_odometry_is_not_fill() {
        let config = EngineConfig::default();
        let mut state = State::new(&config);
        extend(&mut state, 0, 40);
        let mut schedule = Schedule::default();
        schedule.fresh(&state);
        extend(&mut state, 40, 200);
        assert!(state.factor_nnz() > 4 * schedule.nnz_after_resolve);
        assert!(!schedule.filled(&config, &state));
        for k in (10..200).step_by(10) {
            let z = Pose2::new(k as f64 - 1.0, 0.0, 0.0);
            let closure = EdgeInput::new(1, k, z, Information::identity(), EdgeKind::TrustedLoopClosure);
            state.replay(&Op::Edge(closure, Origin::LOCAL), 0.0).unwrap();
        }
        state.solve(0.0).unwrap();
        assert!(schedule.filled(&config, &state));
    }
}
