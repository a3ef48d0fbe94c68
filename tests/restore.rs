//! Saved maps: an engine restored from one holds the same map, and
//! carries on from it to the same optimum as the engine that never
//! stopped.

use slamd::engine::{Engine, EngineConfig};
use slamd::store::MapFile;
use slamd_tests::{feed, max_pose_error, read};
use std::path::Path;

/// Inline re-solves, and every keyframe's step back-substituted (with
/// the wildfire threshold a running engine's estimate lags its own
/// normal equations by up to centimetres; a restored one solves them
/// afresh).
fn deterministic() -> EngineConfig {
    EngineConfig {
        background: false,
        wildfire_threshold: 0.0,
        ..EngineConfig::default()
    }
}

/// Manhattan saved at keyframe 1,750 and read back: the restored engine
/// publishes the same poses, χ² and switches; fed the rest of the stream,
/// it ends at the published optimum 146.077.
#[test]
fn manhattan_saved_at_1750_continues_to_the_optimum() {
    let g = read("manhattanolson3500_g2oversion.g2o");
    let mut first = Engine::new(deterministic());
    feed(&mut first, &g, 0..1750);
    let saved = first.map();
    let bytes = saved.encode();
    let map = MapFile::decode(Path::new("manhattan.map"), &bytes).unwrap();
    assert_eq!(map.keyframes.len(), 1750);
    let mut restored = Engine::restore(deterministic(), map, false).unwrap();
    restored.update();
    let (a, b) = (first.snapshot(), restored.snapshot());
    let pa: Vec<_> = a.poses().map(|(_, p)| p).collect();
    let pb: Vec<_> = b.poses().map(|(_, p)| p).collect();
    assert_eq!(pa.len(), pb.len());
    let moved = max_pose_error(&pa, &pb);
    assert!(moved < 1e-6, "restored poses differ by {moved:e}");
    assert!(
        (a.chi2 - b.chi2).abs() <= 1e-6 * a.chi2,
        "χ² {} against {}",
        b.chi2,
        a.chi2
    );
    assert_eq!(first.switches(), restored.switches());

    feed(&mut restored, &g, 1750..g.len());
    let chi2 = restored.resolve_now().chi2;
    assert!((chi2 - 146.077).abs() < 1e-3, "final χ² {chi2}");
}

/// A map whose edge names a keyframe it does not hold is refused with
/// the reason, not taken up half.
#[test]
fn a_map_that_breaks_the_graph_is_refused() {
    let g = read("manhattanolson3500_g2oversion.g2o");
    let mut engine = Engine::new(deterministic());
    feed(&mut engine, &g, 0..50);
    let mut map = engine.map();
    map.keyframes.truncate(40);
    let err = Engine::restore(deterministic(), map, false).err().unwrap();
    assert!(err.to_string().contains("unknown keyframe"), "{err}");
}

/// A keyframe whose edges never came (its frontend died between the two)
/// is the newest and not in the estimate: the map is still saved, and the
/// restored engine holds it, unjoined, and joins it when its edge comes.
#[test]
fn a_map_saved_with_an_unjoined_newest_keyframe_restores() {
    let g = read("manhattanolson3500_g2oversion.g2o");
    let mut engine = Engine::new(deterministic());
    feed(&mut engine, &g, 0..200);
    engine.add_keyframe(g.id_of(200), None).unwrap();
    engine.update();
    let saved = engine.map();
    assert_eq!(saved.keyframes.len(), 201);
    assert!(!saved.keyframes[200].joined);
    let map = MapFile::decode(Path::new("unjoined.map"), &saved.encode()).unwrap();
    let mut restored = Engine::restore(deterministic(), map, false).unwrap();
    restored.update();
    assert_eq!(restored.snapshot().len(), 200);
    let odometry = g.by_newer()[200].clone();
    for e in odometry {
        restored.add_edge(g.edge_input(e)).unwrap();
    }
    restored.update();
    assert_eq!(restored.snapshot().len(), 201);
}

/// Keyframe timestamps go into the saved map and come back with the
/// restored engine's snapshots; keyframes sent without one keep none.
#[test]
fn keyframe_timestamps_survive_a_saved_map() {
    let g = read("intel_sesync.g2o").prefix(60);
    let mut first = Engine::new(deterministic());
    let stamp = |k: usize| {
        if k.is_multiple_of(3) {
            0
        } else {
            1_000_000_007 * k as u64
        }
    };
    for (k, group) in g.by_newer().iter().enumerate() {
        first.add_keyframe_at(g.id_of(k), None, stamp(k)).unwrap();
        for &e in group {
            first.add_edge(g.edge_input(e)).unwrap();
        }
        first.update();
    }
    let bytes = first.map().encode();
    let map: MapFile = MapFile::decode(Path::new("intel.map"), &bytes).unwrap();
    let saved: Vec<u64> = map.keyframes.iter().map(|k| k.timestamp_ns).collect();
    assert_eq!(saved, (0..60).map(stamp).collect::<Vec<_>>());
    let restored = Engine::restore(deterministic(), map, false).unwrap();
    let snap = restored.snapshot();
    let back: Vec<(u64, u64)> = snap.poses().map(|(id, _)| id).zip(snap.timestamps()).collect();
    let want: Vec<(u64, u64)> = (0..60).map(|k| (g.id_of(k), stamp(k))).collect();
    assert_eq!(back, want);
}
