//! `slamd synth`: write the built-in synthetic world as files.

use anyhow::Context;
use clap::Args;
use slamd::synthetic::{generate, WorldParams};
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
    /// Ground-truth output (`id x y theta`).
    #[arg(long, default_value = "synthetic_truth.txt")]
    pub truth: PathBuf,
}

pub fn run(opts: SynthOpts) -> anyhow::Result<()> {
    let world = generate(&WorldParams {
        poses: opts.poses,
        seed: opts.seed,
        ..Default::default()
    });
    let guess = world.graph.compose_spanning_tree()?;
    let create = |p: &PathBuf| {
        std::fs::File::create(p)
            .map(std::io::BufWriter::new)
            .with_context(|| format!("creating {}", p.display()))
    };
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
