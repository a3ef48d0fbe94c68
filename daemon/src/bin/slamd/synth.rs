//! `slamd synth`: write the built-in synthetic world as files.

use anyhow::Context;
use clap::Args;
use slamd::synthetic::{generate, generate_building, WorldParams};
use std::io::Write;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SynthOpts {
    /// Number of keyframes.
    #[arg(long, default_value_t = 2000)]
    pub poses: usize,
    /// RNG seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Graph output (g2o, noisy edges; vertices hold odometry composed).
    #[arg(long, default_value = "synthetic.g2o")]
    pub out: PathBuf,
    /// Ground-truth output (`id x y theta`; in 3-D a g2o file whose
    /// vertices are the truth, readable by `--ground-truth`).
    #[arg(long, default_value = "synthetic_truth.txt")]
    pub truth: PathBuf,
    /// A 3-D world: the same drive through a building of this many storeys
    /// (`--storeys`, default 3), written as g2o SE3.
    #[arg(long = "3d")]
    pub spatial: bool,
    /// Storeys of the 3-D building.
    #[arg(long, default_value_t = 3)]
    pub storeys: usize,
}

fn create(p: &PathBuf) -> anyhow::Result<std::io::BufWriter<std::fs::File>> {
    std::fs::File::create(p)
        .map(std::io::BufWriter::new)
        .with_context(|| format!("creating {}", p.display()))
}

pub fn run(opts: SynthOpts) -> anyhow::Result<()> {
    let params = WorldParams {
        poses: opts.poses,
        seed: opts.seed,
        ..Default::default()
    };
    if opts.spatial {
        let world = generate_building(&params, opts.storeys);
        let guess = world.graph.compose_spanning_tree()?;
        let mut g = create(&opts.out)?;
        slamd::io::write_g2o(&mut g, &world.graph, &guess)?;
        g.flush()?;
        let mut t = create(&opts.truth)?;
        slamd::io::write_g2o(&mut t, &world.graph, &world.truth)?;
        t.flush()?;
        eprintln!(
            "wrote {} ({} keyframes, {} edges, {} storeys) and {}",
            opts.out.display(),
            world.graph.len(),
            world.graph.edges().len(),
            opts.storeys.max(1),
            opts.truth.display()
        );
        return Ok(());
    }
    let world = generate(&params);
    let guess = world.graph.compose_spanning_tree()?;
    let mut g = create(&opts.out)?;
    slamd::io::write_g2o(&mut g, &world.graph, &guess)?;
    g.flush()?;
    let mut t = create(&opts.truth)?;
    slamd::io::write_pose_table(&mut t, &world.graph, &world.truth)?;
    t.flush()?;
    eprintln!(
        "wrote {} ({} keyframes, {} edges) and {}",
        opts.out.display(),
        world.graph.len(),
        world.graph.edges().len(),
        opts.truth.display()
    );
    Ok(())
}
