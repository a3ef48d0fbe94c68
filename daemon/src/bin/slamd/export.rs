//! `slamd export MAP --out FILE`: a saved map as a g2o graph, or its
//! trajectory as TUM or KITTI.

use anyhow::Context;
use clap::Args;
use slamd::geometry::Pose2;
use slamd::outliers::REJECTED_BELOW;
use slamd::store::MapFile;
use std::io::Write;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ExportOpts {
    /// A saved map (a state directory's `map` file).
    pub map: PathBuf,
    /// The file to write: `.g2o`, the saved estimate as vertices and the
    /// edges as received; `.tum` or `.kitti`, the keyframes in the
    /// estimate as evo reads them (TUM's time: the keyframe's timestamp in
    /// s when every one has one, else its id).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Leave out the loop closures the outlier filter holds wrong.
    #[arg(long)]
    pub drop_rejected: bool,
}

pub fn run(opts: ExportOpts) -> anyhow::Result<()> {
    let mut map = MapFile::<Pose2>::read(&opts.map)?;
    let total = map.edges.len();
    if opts.drop_rejected {
        map.edges.retain(|e| e.switch >= REJECTED_BELOW);
    }
    let graph = map.graph()?;
    let poses: Vec<_> = map.keyframes.iter().map(|k| k.estimate).collect();
    let file =
        std::fs::File::create(&opts.out).with_context(|| format!("creating {}", opts.out.display()))?;
    let mut out = std::io::BufWriter::new(file);
    let written = match slamd::io::Trajectory::of(&opts.out) {
        Some(layout) => {
            // the keyframes in the estimate, not those whose edges never
            // came (they sit at their guess)
            let joined: Vec<_> = map.keyframes.iter().filter(|k| k.joined).collect();
            let ids: Vec<_> = joined.iter().map(|k| k.id).collect();
            let stamps: Vec<_> = joined.iter().map(|k| k.timestamp_ns).collect();
            let at: Vec<_> = joined.iter().map(|k| k.estimate).collect();
            slamd::io::write_trajectory_at(&mut out, layout, &ids, &stamps, &at)
        }
        None => slamd::io::write_g2o(&mut out, &graph, &poses),
    };
    written
        .and_then(|_| out.flush())
        .with_context(|| format!("writing {}", opts.out.display()))?;
    eprintln!(
        "{}: {} keyframes, {} of {} edges",
        opts.out.display(),
        graph.len(),
        graph.edges().len(),
        total
    );
    Ok(())
}
