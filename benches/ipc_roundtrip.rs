//! IPC round trip: an edge published → the snapshot that contains it
//! received, on a tiny graph so that the solve is negligible: each round
//! adds a keyframe and its edge to keyframe 0 (a star, so one keyframe
//! moves), and every `PER_SESSION` rounds the graph starts over.
//!
//! iceoryx2 (the daemon's real path: shared memory plus event wake-ups,
//! IPC thread → engine thread → publisher) against a Unix domain socket
//! server doing the same engine work, interleaved in one run. Each is
//! measured with the threads free to run on any core, and with the daemon's
//! threads and the frontend on one core (`ipc.cpu`): on this VM a wake-up
//! across cores costs several times one on the same core.
//!
//! `cargo bench -p slamd-benches --bench ipc_roundtrip` (target: p50 ≤ 20 µs)

use slamd_client::{
    Config, EdgeInput, EdgeKind, Embedded, Frontend, Information, Pose2, Publish, Server, Snapshots,
};
use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::time::{Duration, Instant};

const SESSIONS: usize = 20;
const PER_SESSION: usize = 500;
const WARMUP: usize = 50;

/// Round `k`'s edge: keyframe 0 to the new keyframe `k + 1`.
fn edge(k: usize) -> EdgeInput {
    let a = k as f64 * 0.1;
    EdgeInput::new(
        0,
        k as u64 + 1,
        Pose2::new(a.cos(), a.sin(), a),
        Information::identity(),
        EdgeKind::Other,
    )
}

/// An engine configuration that never re-solves: the transport is measured,
/// not the polish.
fn quiet_config(namespace: String, cpu: Option<usize>) -> Config {
    let mut config = Config {
        namespace,
        ..Config::default()
    };
    config.engine.resolve_every_edges = 0;
    config.engine.resolve_fill_ratio = 0.0;
    config.ipc.cpu = cpu;
    config
}

fn percentiles(mut v: Vec<f64>) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.99), at(0.999))
}

/// One session through a daemon (in this process, on its own threads).
fn iceoryx2(session: usize, cpu: Option<usize>) -> Vec<f64> {
    let config = quiet_config(format!("slamd-bench-rt-{}-{session}", std::process::id()), cpu);
    let server = Server::spawn(config.clone()).expect("daemon");
    let mut snaps = Snapshots::open(&config.namespace).expect("snapshots");
    let mut f = Frontend::connect(&config).expect("frontend");
    Frontend::add_keyframe(&mut f, 0, 0, None).unwrap();
    let mut out = Vec::with_capacity(PER_SESSION);
    for k in 0..PER_SESSION {
        Frontend::add_keyframe(&mut f, k as u64 + 1, 0, None).unwrap();
        let t0 = Instant::now();
        let seq = Frontend::add_edge(&mut f, &edge(k)).unwrap();
        Frontend::flush(&mut f).unwrap();
        loop {
            let s = snaps
                .wait(Duration::from_secs(5))
                .unwrap()
                .expect("daemon answers");
            if s.header().ack_of(f.id()).is_some_and(|a| a >= seq) {
                assert_eq!(s.poses().len(), k + 2);
                break;
            }
        }
        if k >= WARMUP {
            out.push(t0.elapsed().as_secs_f64() * 1e6);
        }
    }
    drop(snaps);
    server.join().expect("clean stop");
    out
}

/// The same exchange over a Unix socket: an edge's bytes in, the engine
/// takes the keyframe and edge and updates, a header plus the poses out.
fn unix_socket(session: usize, cpu: Option<usize>) -> Vec<f64> {
    let path = std::env::temp_dir().join(format!("slamd-bench-{}-{session}.sock", std::process::id()));
    let _ = std::fs::remove_file(&path);
    let listener = UnixListener::bind(&path).unwrap();
    let server = std::thread::spawn(move || {
        if let Some(cpu) = cpu {
            slamd::affinity::pin_current_thread(cpu);
        }
        let (mut conn, _) = listener.accept().unwrap();
        let mut engine = Embedded::new(&quiet_config(String::new(), None));
        engine.add_keyframe(0, 0, None).unwrap();
        let mut msg = [0u8; std::mem::size_of::<slamd_protocol::Edge>()];
        let mut k = 0;
        while conn.read_exact(&mut msg).is_ok() {
            engine.add_keyframe(k as u64 + 1, 0, None).unwrap();
            engine.add_edge(&edge(k)).unwrap();
            engine.flush().unwrap();
            k += 1;
            let snap = engine.snapshot();
            let mut reply = Vec::with_capacity(200 + 32 * (k + 1));
            reply.extend_from_slice(&[0u8; 200]); // a header's worth
            for (id, p) in snap.poses() {
                for v in [id as f64, p.x, p.y, p.theta] {
                    reply.extend_from_slice(&v.to_le_bytes());
                }
            }
            conn.write_all(&(reply.len() as u64).to_le_bytes()).unwrap();
            conn.write_all(&reply).unwrap();
        }
    });
    let mut client = UnixStream::connect(&path).unwrap();
    let mut reply = vec![0u8; 200 + 32 * (PER_SESSION + 1)];
    let mut out = Vec::with_capacity(PER_SESSION);
    for k in 0..PER_SESSION {
        let t0 = Instant::now();
        client
            .write_all(&[k as u8; std::mem::size_of::<slamd_protocol::Edge>()])
            .unwrap();
        let mut len = [0u8; 8];
        client.read_exact(&mut len).unwrap();
        client
            .read_exact(&mut reply[..u64::from_le_bytes(len) as usize])
            .unwrap();
        if k >= WARMUP {
            out.push(t0.elapsed().as_secs_f64() * 1e6);
        }
    }
    drop(client);
    server.join().unwrap();
    let _ = std::fs::remove_file(&path);
    out
}

fn main() {
    // criterion passes its own flags to bench targets; this one takes none
    println!("| transport | threads | p50 µs | p99 µs | p99.9 µs | rounds |");
    println!("|---|---|---|---|---|---|");
    for (placement, cpu) in [("any core", None), ("one core (ipc.cpu = 0)", Some(0))] {
        let (mut ice, mut uds) = (Vec::new(), Vec::new());
        std::thread::scope(|s| {
            s.spawn(|| {
                if let Some(cpu) = cpu {
                    slamd::affinity::pin_current_thread(cpu);
                }
                // interleave the two so that both see the same machine load
                for session in 0..SESSIONS {
                    ice.extend(iceoryx2(session, cpu));
                    uds.extend(unix_socket(session, cpu));
                }
            });
        });
        let n = ice.len();
        for (name, v) in [("iceoryx2 (slamd daemon)", ice), ("Unix domain socket", uds)] {
            let (p50, p99, p999) = percentiles(v);
            println!("| {name} | {placement} | {p50:.1} | {p99:.1} | {p999:.1} | {n} |");
        }
    }
}
