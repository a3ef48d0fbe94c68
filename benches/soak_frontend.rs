//! One frontend of `benches/soak.py`: streams a seeded synthetic world to
//! a running daemon and reports what the daemon acknowledged.
//!
//! ```text
//! slamd-soak-frontend NAMESPACE WORLD RESTART KEYFRAMES RATE UNTIL_S
//! ```
//!
//! RESTART counts the frontends that streamed WORLD before this one (0
//! for the first; one more after each kill). The world is `slamd synth`'s
//! with seed `1000 · WORLD + RESTART`; its keyframe ids start at
//! `(1000 · WORLD + RESTART) · 2³²`, so no two frontends share an id.
//! World 0's first frontend holds keyframe 0, the daemon's gauge; every
//! other frontend is tied to it by one exact odometry edge from keyframe 0
//! to its first keyframe, 300 m east per world and 300 m north per
//! restart, so all of them join one map. It publishes at most RATE
//! keyframes a second, each with its edges, and once a second prints
//! `acked N`: its first N keyframes are acknowledged (on disk, with a
//! state directory). After the last one it waits for the acknowledgement,
//! prints `done N`, and stays connected, polling, until UNTIL_S seconds
//! after its start.

use slamd::engine::EdgeInput;
use slamd::geometry::Pose2;
use slamd::graph::{EdgeKind, Information};
use slamd::synthetic::{generate, WorldParams};
use slamd_protocol::{Endpoint, Frontend};
use std::time::{Duration, Instant};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [namespace, world, restart, keyframes, rate, until] = args.as_slice() else {
        return Err("usage: slamd-soak-frontend NAMESPACE WORLD RESTART KEYFRAMES RATE UNTIL_S".into());
    };
    let (world, restart): (u64, u64) = (world.parse()?, restart.parse()?);
    let (keyframes, rate, until): (usize, f64, f64) = (keyframes.parse()?, rate.parse()?, until.parse()?);
    let tag = 1000 * world + restart;
    let w = generate(&WorldParams {
        poses: keyframes,
        seed: tag,
        ..WorldParams::default()
    });
    let base = tag << 32;
    let mut frontend = Frontend::connect(Endpoint::new(namespace))?;
    let mut sequences = Vec::with_capacity(keyframes);
    let start = Instant::now();
    let mut report = Instant::now();
    for (k, group) in w.graph.by_newer().into_iter().enumerate() {
        sequences.push(frontend.add_keyframe(base + k as u64, 0, None)?);
        if k == 0 && base != 0 {
            let place = Pose2::new(300.0 * world as f64, 300.0 * restart as f64, 0.0);
            let tie = EdgeInput::new(0, base, place, Information::identity(), EdgeKind::Odometry);
            frontend.add_edge(&tie)?;
        }
        // the edges that keyframe k completes, in this frontend's ids
        for e in group {
            let mut edge = w.graph.edge_input(e);
            (edge.from, edge.to) = (base + edge.from, base + edge.to);
            frontend.add_edge(&edge)?;
        }
        frontend.flush()?;
        let due = start + Duration::from_secs_f64((k + 1) as f64 / rate);
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        if report.elapsed() >= Duration::from_secs(1) {
            print_acked("acked", &sequences, frontend.acknowledged());
            report = Instant::now();
        }
    }
    let last = frontend.last_sequence();
    if !frontend.wait_acknowledged(last, Duration::from_secs(120))? {
        return Err("the daemon did not acknowledge the last keyframe within 120 s".into());
    }
    print_acked("done", &sequences, frontend.acknowledged());
    let until = start + Duration::from_secs_f64(until);
    while Instant::now() < until {
        frontend.poll()?;
        std::thread::sleep(Duration::from_millis(500));
    }
    Ok(())
}

/// Prints how many of the first keyframes (by message number) the daemon
/// acknowledged.
fn print_acked(word: &str, sequences: &[u64], acked: u64) {
    let n = sequences.partition_point(|&s| s <= acked);
    println!("{word} {n}");
}
