//! Rebuilding a [`State`]: the polish that moves the linearisation point
//! ([`polish_model`]) and the fresh factor at it
//! ([`State::factorise`]); both together are [`rebuild`]. A background re-solve runs the two halves on
//! its own thread, the foreground runs [`rebuild`] inline.

use super::model::Model;
use super::op::Polish;
use super::pose::EnginePose;
use super::state::State;
use super::EngineConfig;
use crate::sparse::FactorError;
use std::sync::atomic::AtomicBool;

/// A fresh state from `model`: polished from `start` as `polish` says,
/// re-ordered with the newest `recent_last` keyframes last,
/// refactorised.
pub fn rebuild<P: EnginePose>(
    mut model: Model<P>,
    start: &[P],
    polish: Polish,
    config: &EngineConfig,
) -> Result<State<P>, FactorError> {
    let lin = polish_model(&mut model, start, polish, config, &AtomicBool::new(false));
    State::factorise(model, lin, config)
}

/// The first half of [`rebuild`]: unjoins what no weighted edge
/// holds and polishes `model` from `start` as `polish` says, setting
/// its switches and georeference; returns the linearisation point of
/// every keyframe. Once `stop` is set the polish ends where it is and
/// the georeference is left as it was.
pub fn polish_model<P: EnginePose>(
    model: &mut Model<P>,
    start: &[P],
    polish: Polish,
    config: &EngineConfig,
    stop: &AtomicBool,
) -> Vec<P> {
    model.unjoin_unconstrained();
    let n = model.graph.len();
    let mut lin = start.to_vec();
    lin.resize(n, P::IDENTITY);
    if polish != Polish::None {
        let (joined, compact) = model.compact_joined();
        let started = std::time::Instant::now();
        let mut poses = model.robust_polish(config, &compact, &joined, &lin, polish, stop);
        tracing::debug!(seconds = started.elapsed().as_secs_f64(), ?polish, "Polished.");
        if !stop.load(std::sync::atomic::Ordering::Relaxed) {
            let (edges, _) = model.compact_edges(&compact, Model::<P>::weight);
            model.georeference(&config.gps, &edges, &compact, &mut poses, &config.polish);
        }
        for (c, &k) in joined.iter().enumerate() {
            lin[k] = poses[c];
        }
    }
    lin
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::state::tests::{close, keyframe, odometry};
    use crate::engine::{EdgeInput, Op};
    use crate::geometry::Pose2;
    use crate::graph::{EdgeKind, Information, KeyframeId};
    use crate::outliers::{OutlierConfig, OFF_BELOW};
    use slamd_protocol::codec::Origin;

    /// Six keyframes 1 m apart along x, then two loop closures from 0 to
    /// 5 (edges 5 and 6): one `x` metres long (let in on arrival when near
    /// 5) and one far off (turned away); solved.
    fn line_closed(config: &EngineConfig, x: f64) -> State {
        let step = Pose2::new(1.0, 0.0, 0.0);
        let mut state = State::new(config);
        for k in 0..6 {
            state.replay(&keyframe(k), 0.0).unwrap();
            if k > 0 {
                state.replay(&odometry(k - 1, k, step), 0.0).unwrap();
            }
        }
        for z in [Pose2::new(x, 0.0, 0.0), Pose2::new(-40.0, 30.0, 2.0)] {
            let closure = EdgeInput::new(0, 5, z, Information::identity(), EdgeKind::LoopClosure);
            state.replay(&Op::Edge(closure, Origin::LOCAL), 0.0).unwrap();
        }
        state.solve(0.0).unwrap();
        state
    }

    /// A loop closure let in on arrival is marked until a multi-start
    /// re-solve has judged it (the closing one gets a start without the
    /// marked ones); one turned away on arrival is not marked.
    #[test]
    fn loop_closures_let_in_on_arrival_are_marked_until_a_full_resolve() {
        let config = EngineConfig::default();
        let state = line_closed(&config, 5.0);
        let (agreeing, wrong) = (5, 6);
        assert!(state.model.edges[agreeing].switch >= OFF_BELOW && state.model.edges[agreeing].admitted);
        assert!(state.model.edges[wrong].switch < OFF_BELOW && !state.model.edges[wrong].admitted);
        // a relinearisation is no judgement; a multi-start re-solve is
        let estimate = state.estimate().to_vec();
        let relinearised = rebuild(state.model.clone(), &estimate, Polish::None, &config).unwrap();
        assert!(relinearised.model.edges[agreeing].admitted);
        let resolved = rebuild(state.model.clone(), &estimate, Polish::Full, &config).unwrap();
        assert!(!resolved.model.edges.iter().any(|s| s.admitted));
    }

    /// The start without the loop closures let in on arrival: the closing
    /// re-solve's always, every multi-start re-solve's with
    /// `unadmitted_start`, the inline polish's never.
    #[test]
    fn the_start_without_admitted_loop_closures_goes_where_configured() {
        let config = EngineConfig::default();
        // the loop closure let in pulls keyframe 5 by 0.3 m
        let state = line_closed(&config, 5.3);
        assert!(state.model.edges[5].admitted && !state.model.edges[6].admitted);
        let (joined, compact) = state.model.compact_joined();
        let (_, ids) = state.model.compact_edges(&compact, |m, e| m.edges[e].scale);
        let initial: Vec<Pose2> = joined.iter().map(|&k| state.estimate()[k]).collect();
        let starts = |config: &EngineConfig, polish| {
            state
                .model
                .starts(config, &compact, &joined, &initial, &ids, polish)
        };
        let always = EngineConfig {
            outliers: OutlierConfig {
                unadmitted_start: true,
                ..config.outliers
            },
            ..config.clone()
        };
        // the estimate, the two-stage solution under the switches, under none
        assert_eq!(starts(&config, Polish::Full).len(), 3);
        assert_eq!(starts(&config, Polish::Inline).len(), 1);
        assert_eq!(starts(&always, Polish::Inline).len(), 1);
        for (config, polish) in [(&config, Polish::Closing), (&always, Polish::Full)] {
            let s = starts(config, polish);
            assert_eq!(s.len(), 4);
            // under the switches keyframe 5 is pulled toward 5.3; without
            // the loop closure let in, odometry alone puts it at 5
            assert!(s[1][5].x > 5.1, "{:?}", s[1][5]);
            assert!((s[3][5].x - 5.0).abs() < 1e-9, "{:?}", s[3][5]);
        }
    }

    /// The dead-reckoned start: the closing re-solve's, once a loop
    /// closure weighs in that was not let in on arrival (a re-solve let it
    /// in, so the start without the admitted ones still holds it), with
    /// every loop closure out; no other polish takes it.
    #[test]
    fn the_closing_resolve_starts_from_the_dead_reckoned_map_too() {
        let config = EngineConfig::default();
        let mut state = line_closed(&config, 5.3);
        let (joined, compact) = state.model.compact_joined();
        let initial: Vec<Pose2> = joined.iter().map(|&k| state.estimate()[k]).collect();
        let (_, ids) = state.model.compact_edges(&compact, |m, e| m.edges[e].scale);
        let starts = |state: &State, polish| {
            state
                .model
                .starts(&config, &compact, &joined, &initial, &ids, polish)
        };
        // only admitted ones weigh in: it would be the start without them
        assert_eq!(starts(&state, Polish::Closing).len(), 4);
        // the far one let in by a re-solve at switch 0.6: the estimate,
        // under the switches, under none, without the admitted one, and
        // dead-reckoned, where keyframe 5 sits where odometry puts it
        state.model.edges[6].switch = 0.6;
        let closing = starts(&state, Polish::Closing);
        assert_eq!(closing.len(), 5);
        assert!(
            (closing[4][5].x - 5.0).abs() < 1e-9 && closing[4][5].y.abs() < 1e-9,
            "{:?}",
            closing[4][5]
        );
        // the start without the admitted one still feels the far one
        assert!((closing[3][5].x - 5.0).abs() > 0.1, "{:?}", closing[3][5]);
        // a scheduled re-solve: no rescue start for a switch of 0.6
        assert_eq!(starts(&state, Polish::Full).len(), 2);
        assert_eq!(starts(&state, Polish::FullInline).len(), 3);
    }

    /// The start under no switches rescues loop closures held wrong; a
    /// scheduled re-solve takes it only while one is (below 0.5), the
    /// closing one whenever a switch is below 1.
    #[test]
    fn a_scheduled_resolve_takes_the_rescue_start_only_while_one_is_held_wrong() {
        let config = EngineConfig::default();
        let mut state = line_closed(&config, 5.0);
        let wrong = 6;
        let mut counts = |switch: f64| {
            state.model.edges[wrong].switch = switch;
            let (joined, compact) = state.model.compact_joined();
            let (_, ids) = state.model.compact_edges(&compact, |m, e| m.edges[e].scale);
            let initial: Vec<Pose2> = joined.iter().map(|&k| state.estimate()[k]).collect();
            let starts = |polish| {
                state
                    .model
                    .starts(&config, &compact, &joined, &initial, &ids, polish)
                    .len()
            };
            (starts(Polish::Full), starts(Polish::FullInline))
        };
        // held wrong: the estimate, under the switches, under none
        assert_eq!(counts(0.3), (3, 3));
        // only down-weighted: the scheduled re-solve skips the rescue
        assert_eq!(counts(0.7), (2, 3));
        // every switch at 1: neither takes it
        assert_eq!(counts(1.0), (2, 2));
    }

    /// A ring of keyframes with a loop closure back `span` keyframes from
    /// each, every measurement exact, replayed op by op: the reordered
    /// state solves to the same estimate with fewer factor entries than
    /// the state that appended each keyframe to the ordering.
    #[test]
    fn a_reordered_state_solves_the_same_system_with_less_fill() {
        let (n, span) = (120, 30);
        let truth: Vec<Pose2> = (0..n)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / n as f64;
                Pose2::new(10.0 * a.cos(), 10.0 * a.sin(), a + 0.5)
            })
            .collect();
        let between = |i: usize, j: usize| truth[i].inverse().compose(&truth[j]);
        let config = EngineConfig::default();
        let mut state = State::new(&config);
        for k in 0..n {
            state.replay(&keyframe(k as KeyframeId), 0.0).unwrap();
            if k > 0 {
                state
                    .replay(
                        &odometry(k as KeyframeId - 1, k as KeyframeId, between(k - 1, k)),
                        0.0,
                    )
                    .unwrap();
            }
            if k >= span {
                let z = between(k - span, k);
                let closure = EdgeInput::new(
                    (k - span) as KeyframeId,
                    k as KeyframeId,
                    z,
                    Information::identity(),
                    EdgeKind::LoopClosure,
                );
                state.replay(&Op::Edge(closure, Origin::LOCAL), 0.0).unwrap();
            }
        }
        state.solve(0.0).unwrap();
        let mut fresh = state.reordered(&config).unwrap();
        fresh.solve(0.0).unwrap();
        assert!(
            fresh.factor_nnz() < state.factor_nnz(),
            "{} entries reordered, {} appended",
            fresh.factor_nnz(),
            state.factor_nnz()
        );
        for k in 0..n {
            let (a, b) = (state.estimate()[k], fresh.estimate()[k]);
            assert!(close(a, b), "keyframe {k}: {a:?} against {b:?}");
            // exact measurements: both are the world itself, up to the gauge
            let g = truth[0].inverse().compose(&truth[k]);
            assert!(
                (a.x - g.x).abs() < 1e-9 && (a.y - g.y).abs() < 1e-9,
                "keyframe {k}"
            );
        }
        assert!(fresh.chi2() < 1e-18);
    }
}
