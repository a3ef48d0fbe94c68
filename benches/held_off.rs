//! How many true loop closures the outlier filter holds off on synthetic
//! worlds, and what each costs the graph (its Δχ², see
//! `slamd_tests::held_off`): the measurement behind the property test in
//! `tests/true_loop_closures.rs`.
//!
//! ```text
//! slamd-held-off WORLDS [--any-pair]
//! ```
//!
//! World `s` (for `s` in `0..WORLDS`) is `slamd synth --poses 300 --seed s`
//! with one more loop closure measured exactly from the ground truth,
//! between two keyframes drawn from the seed: a revisit (true positions
//! within 2 m), or with `--any-pair` any two keyframes. Each replays inline
//! and closes with the final re-solve. Prints one markdown table.

use slamd::engine::EngineConfig;
use slamd::robust::DEFAULT_PHI;
use slamd::synthetic::{generate, World, WorldParams};
use slamd_tests::held_off::{held_off, with_exact_closure, HeldOff};

const POSES: usize = 300;

/// SplitMix64: the pair of world `seed`, without a dependency.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The two keyframes `world`'s (seed `seed`) exact loop closure joins.
fn pair(world: &World, seed: u64, any: bool) -> (usize, usize) {
    let truth = &world.truth;
    let mut state = seed;
    loop {
        let a = (splitmix(&mut state) % POSES as u64) as usize;
        let b = (splitmix(&mut state) % POSES as u64) as usize;
        let near = (truth[a].x - truth[b].x).hypot(truth[a].y - truth[b].y) <= 2.0;
        if a.abs_diff(b) >= 2 && (any || near) {
            return (a, b);
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let any = args.iter().any(|a| a == "--any-pair");
    let worlds: u64 = match args.iter().find(|a| !a.starts_with("--")) {
        Some(n) => n.parse()?,
        None => return Err("usage: slamd-held-off WORLDS [--any-pair]".into()),
    };
    let config = EngineConfig {
        background: false,
        ..EngineConfig::default()
    };
    let (mut alone, mut together) = (Vec::<HeldOff>::new(), Vec::<HeldOff>::new());
    let (mut touched, mut exact) = (0, 0);
    for seed in 0..worlds {
        let world = generate(&WorldParams {
            poses: POSES,
            seed,
            ..WorldParams::default()
        });
        let (a, b) = pair(&world, seed, any);
        let g = with_exact_closure(world, a, b);
        let off = held_off(&g, config.clone());
        touched += usize::from(!off.is_empty());
        exact += off.iter().filter(|h| h.edge == g.edges().len() - 1).count();
        match off.len() {
            0 => {}
            1 => alone.extend(off),
            _ => together.extend(off),
        }
    }
    let least = |v: &[HeldOff], f: fn(&HeldOff) -> f64| v.iter().map(f).fold(f64::INFINITY, f64::min);
    let all: Vec<HeldOff> = alone.iter().chain(&together).copied().collect();
    println!("| exact loop closure | worlds | worlds with any held off | held off | least Δχ² alone | least Δχ² with others | least own χ² | own χ² ≤ Φ | the exact one |");
    println!("|---|---|---|---|---|---|---|---|---|");
    println!(
        "| {} | {worlds} | {touched} | {} | {:.2} | {:.2} | {:.2} | {} | {exact} |",
        if any { "any pair" } else { "a revisit" },
        all.len(),
        least(&alone, |h| h.delta_chi2),
        least(&together, |h| h.delta_chi2),
        least(&all, |h| h.own_chi2),
        all.iter().filter(|h| h.own_chi2 <= DEFAULT_PHI).count(),
    );
    Ok(())
}
