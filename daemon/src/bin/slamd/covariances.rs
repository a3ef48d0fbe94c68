//! `slamd solve --covariances FILE`: every keyframe's marginal covariance
//! at the solution ([`Engine::marginal`]).

use anyhow::Context;
use slamd::engine::{upper_triangle, Engine, EngineConfig, EnginePose};
use slamd::graph::PoseGraph;
use slamd::store::MapFile;
use std::io::Write;
use std::path::Path;

/// Writes one line per keyframe: its id, then the upper triangle of its
/// covariance row by row, in its own frame (6 numbers over `x y θ`, or 21
/// over `x y z rx ry rz`). The graph is factorised at `poses`, with the
/// robust solve's `switches` where it has them (a loop closure switched
/// off counts 0). The first keyframe is the gauge: its rows are 0.
/// Returns the seconds the covariances took, in all and the most one
/// took.
pub fn write<P: EnginePose>(
    path: &Path,
    graph: &PoseGraph<P>,
    poses: &[P],
    switches: Option<&[f64]>,
) -> anyhow::Result<(f64, f64)> {
    let mut map = MapFile::solved(graph, poses);
    if let Some(s) = switches {
        for (edge, &s) in map.edges.iter_mut().zip(s) {
            edge.switch = s;
        }
    }
    let mut config = EngineConfig {
        background: false,
        ..EngineConfig::default()
    };
    config.outliers.enabled = false;
    let mut engine = Engine::<P>::restore(config, map, false).context("factorising the solution")?;
    let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = std::io::BufWriter::new(file);
    let axes = if P::DOF == 3 {
        "x y theta"
    } else {
        "x y z rx ry rz"
    };
    writeln!(
        w,
        "# id, then the covariance's upper triangle row by row over {axes} (the pose's own frame; m, rad)"
    )?;
    let (mut total, mut most) = (0.0, 0.0_f64);
    for k in graph.keyframes() {
        let start = std::time::Instant::now();
        let sigma = engine.marginal(k.id)?;
        let took = start.elapsed().as_secs_f64();
        total += took;
        most = most.max(took);
        let mut line = k.id.to_string();
        for v in upper_triangle(&sigma) {
            line.push_str(&format!(" {v:e}"));
        }
        writeln!(w, "{line}")?;
    }
    w.flush()?;
    Ok((total, most))
}
