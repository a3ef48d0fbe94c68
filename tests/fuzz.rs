//! Hostile input: the wire decoder and the graph readers take arbitrary
//! values and bytes, and mutated valid input, without panicking; every
//! refusal is typed (a rejection reason, or a read error naming its line).
//!
//! A few thousand cases run with the tests. A million of each:
//! `PROPTEST_CASES=1000000 cargo test --release -p slamd-tests --test integration fuzz::`

use proptest::prelude::*;
use slamd::geometry::Pose2;
use slamd::graph::{Information, Information6, Pose3};
use slamd::io::{parse_graph_with, Format, OnInvalid, ReadErrorKind};
use slamd_protocol::codec::{edge_in, gps_in, keyframe_in};
use slamd_protocol::{Edge, GpsFix, Keyframe, RejectionReason, PROTOCOL_VERSION};
use slamd_tests::dataset;
use std::path::Path;

/// Cases per property unless PROPTEST_CASES says otherwise.
const CASES: u32 = 1000;

fn config() -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(CASES);
    ProptestConfig {
        cases,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// Any double, with the troublesome ones often.
fn number() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -1e3..1e3f64,
        2 => any::<f64>(),
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(0.0),
    ]
}

/// A protocol version, usually the right one.
fn version() -> impl Strategy<Value = u32> {
    prop_oneof![4 => Just(PROTOCOL_VERSION), 1 => any::<u32>()]
}

/// A dimension, usually 2 or 3.
fn dimension() -> impl Strategy<Value = u32> {
    prop_oneof![4 => 2u32..4, 1 => any::<u32>()]
}

fn edge() -> impl Strategy<Value = Edge> {
    (
        (0u64..6, 0u64..6, any::<u32>(), any::<u64>()),
        prop::array::uniform7(number()),
        prop::array::uniform21(number()),
        (
            prop_oneof![3 => 0u32..3, 1 => any::<u32>()],
            version(),
            dimension(),
        ),
    )
        .prop_map(
            |((from, to, frontend, sequence), measurement, information, (kind, protocol, dimension))| Edge {
                from,
                to,
                measurement,
                information,
                kind,
                frontend,
                sequence,
                protocol,
                dimension,
            },
        )
}

fn keyframe() -> impl Strategy<Value = Keyframe> {
    (
        (
            any::<u64>(),
            any::<u64>(),
            prop::array::uniform7(number()),
            any::<u32>(),
        ),
        (any::<u32>(), any::<u64>(), version(), dimension()),
    )
        .prop_map(
            |((id, timestamp_ns, guess, has_guess), (frontend, sequence, protocol, dimension))| Keyframe {
                id,
                timestamp_ns,
                guess,
                has_guess,
                frontend,
                sequence,
                protocol,
                dimension,
            },
        )
}

fn fix() -> impl Strategy<Value = GpsFix> {
    (
        (
            any::<u64>(),
            prop_oneof![-100.0..100.0f64, number()],
            prop_oneof![-200.0..200.0f64, number()],
        ),
        (
            number(),
            [number(), number(), number(), number()],
            number(),
            any::<u32>(),
        ),
        (any::<u32>(), any::<u64>(), version(), any::<u32>()),
    )
        .prop_map(
            |(
                (keyframe, latitude, longitude),
                (altitude, covariance, altitude_variance, has_altitude),
                (frontend, sequence, protocol, reserved),
            )| GpsFix {
                keyframe,
                latitude,
                longitude,
                altitude,
                covariance,
                altitude_variance,
                has_altitude,
                frontend,
                sequence,
                protocol,
                reserved,
            },
        )
}

/// The first lines of a shared dataset, as valid input to mutate.
fn head(name: &str, lines: usize) -> String {
    let text = std::fs::read_to_string(dataset(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    text.lines().take(lines).map(|l| format!("{l}\n")).collect()
}

/// One edit of a text: a token replaced, a token removed, a line repeated,
/// or the text cut at a byte.
#[derive(Clone, Debug)]
enum Mutation {
    Replace(usize, &'static str),
    Remove(usize),
    Repeat(usize),
    Cut(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let token = prop::sample::select(vec![
        "nan",
        "inf",
        "-inf",
        "-1",
        "0",
        "1e309",
        "x",
        "18446744073709551616",
        "-0",
        "1e-320",
        "EDGE_SE2",
        "VERTEX2",
        "#",
    ]);
    prop_oneof![
        (any::<usize>(), token).prop_map(|(i, t)| Mutation::Replace(i, t)),
        any::<usize>().prop_map(Mutation::Remove),
        any::<usize>().prop_map(Mutation::Repeat),
        any::<usize>().prop_map(Mutation::Cut),
    ]
}

fn mutate(text: &str, edits: &[Mutation]) -> String {
    let mut lines: Vec<Vec<String>> = text
        .lines()
        .map(|l| l.split_whitespace().map(str::to_owned).collect())
        .collect();
    let mut cut = None;
    for m in edits {
        let tokens: usize = lines.iter().map(Vec::len).sum();
        let locate = |lines: &Vec<Vec<String>>, mut i: usize| {
            for (n, l) in lines.iter().enumerate() {
                if i < l.len() {
                    return Some((n, i));
                }
                i -= l.len();
            }
            None
        };
        match *m {
            Mutation::Replace(i, t) if tokens > 0 => {
                if let Some((n, k)) = locate(&lines, i % tokens) {
                    lines[n][k] = t.to_owned();
                }
            }
            Mutation::Remove(i) if tokens > 0 => {
                if let Some((n, k)) = locate(&lines, i % tokens) {
                    lines[n].remove(k);
                }
            }
            Mutation::Repeat(i) if !lines.is_empty() => {
                let n = i % lines.len();
                lines.insert(n, lines[n].clone());
            }
            Mutation::Cut(i) => cut = Some(i),
            _ => {}
        }
    }
    let out: String = lines.iter().map(|l| l.join(" ") + "\n").collect();
    match cut {
        Some(i) if !out.is_empty() => {
            let mut at = i % out.len();
            while !out.is_char_boundary(at) {
                at -= 1;
            }
            out[..at].to_owned()
        }
        _ => out,
    }
}

/// Parses `text` both ways and checks what comes out: a refusal names a
/// line (and is never an I/O error); a graph holds only finite
/// measurements and valid information; skipping never refuses a line that
/// refusing accepts.
fn check_reader(text: &str, format: Format) {
    let path = Path::new("fuzz.txt");
    let strict = parse_graph_with(path, text, format, OnInvalid::Refuse);
    let lenient = parse_graph_with(path, text, format, OnInvalid::Skip);
    for result in [&strict, &lenient] {
        match result {
            Ok((graph, skipped)) => {
                for e in graph.edges() {
                    assert!(e.measurement.is_finite(), "{e:?}");
                    assert!(Information::from_upper(e.information.upper()).is_ok(), "{e:?}");
                    assert_ne!(e.from, e.to);
                }
                for s in skipped {
                    assert!(s.line.is_some(), "{s}");
                    assert!(!matches!(s.kind, ReadErrorKind::Io(_)), "{s}");
                }
            }
            Err(e) => assert!(!matches!(e.kind, ReadErrorKind::Io(_)), "{e}"),
        }
    }
    if let (Ok((a, _)), Ok((b, skipped))) = (&strict, &lenient) {
        assert!(skipped.is_empty());
        assert_eq!(a.edges().len(), b.edges().len());
    }
    if let Err(e) = &strict {
        // a line-level refusal is skipped instead; whole-graph ones stay
        if e.line.is_some() {
            let (_, skipped) = lenient.as_ref().unwrap_or_else(|l| panic!("{e} / {l}"));
            assert!(skipped.iter().any(|s| s.line == e.line), "{e}");
        }
    }
}

proptest! {
    #![proptest_config(config())]

    /// An edge either decodes to finite numbers, a valid kind, distinct
    /// ends and positive-definite information, or is rejected with a
    /// reason, addressed to its sender.
    #[test]
    fn any_edge_message_decodes_or_is_rejected(m in edge()) {
        match edge_in::<Pose2>(&m) {
            Ok((o, e)) => {
                prop_assert_eq!((o.frontend, o.sequence), (m.frontend, m.sequence));
                prop_assert_eq!((m.protocol, m.dimension), (PROTOCOL_VERSION, 2));
                prop_assert!(e.measurement.is_finite() && e.from != e.to);
                prop_assert!(Information::from_upper(e.information.upper()).is_ok());
            }
            Err(r) => {
                prop_assert_eq!((r.frontend, r.sequence), (m.frontend, m.sequence));
                prop_assert_ne!(r.reason(), RejectionReason::Unknown);
                prop_assert!(!r.text().is_empty());
            }
        }
        match edge_in::<Pose3>(&m) {
            Ok((_, e)) => {
                prop_assert_eq!((m.protocol, m.dimension), (PROTOCOL_VERSION, 3));
                prop_assert!(e.measurement.is_finite() && e.from != e.to);
                prop_assert!((e.measurement.rotation.norm() - 1.0).abs() < 1e-12);
                prop_assert!(Information6::from_upper(e.information.upper()).is_ok());
            }
            Err(r) => {
                prop_assert_eq!((r.frontend, r.sequence), (m.frontend, m.sequence));
                prop_assert_ne!(r.reason(), RejectionReason::Unknown);
            }
        }
    }

    #[test]
    fn any_keyframe_message_decodes_or_is_rejected(m in keyframe()) {
        if let Ok((_, k)) = keyframe_in::<Pose3>(&m) {
            prop_assert_eq!(m.dimension, 3);
            prop_assert!(k.guess.is_none_or(|g| g.is_finite()));
        }
        match keyframe_in::<Pose2>(&m) {
            Ok((o, k)) => {
                prop_assert_eq!((o.frontend, o.sequence, k.id, k.timestamp_ns), (m.frontend, m.sequence, m.id, m.timestamp_ns));
                prop_assert!(k.guess.is_none_or(|g| g.is_finite()));
            }
            Err(r) => {
                prop_assert_eq!((r.frontend, r.sequence), (m.frontend, m.sequence));
                prop_assert_ne!(r.reason(), RejectionReason::Unknown);
            }
        }
    }

    #[test]
    fn any_fix_message_decodes_or_is_rejected(m in fix()) {
        match gps_in(&m) {
            Ok((_, f)) => {
                let p = f.position;
                prop_assert!(p.lat.abs() <= 90.0 && p.lon.abs() <= 180.0 && p.height.is_finite());
                prop_assert!(slamd::gps::check_covariance(f.covariance).is_ok());
            }
            Err(r) => {
                prop_assert_eq!((r.frontend, r.sequence), (m.frontend, m.sequence));
                prop_assert_ne!(r.reason(), RejectionReason::Unknown);
            }
        }
    }

    /// Arbitrary bytes (as the text a reader sees) in every format.
    #[test]
    fn readers_take_arbitrary_text(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let text = String::from_utf8_lossy(&bytes);
        for format in [Format::G2o, Format::Toro, Format::Isam] {
            check_reader(&text, format);
        }
    }

    /// Real files with a few tokens replaced or removed, lines repeated, or
    /// cut short.
    #[test]
    fn readers_take_mutated_files(edits in prop::collection::vec(mutation(), 1..6)) {
        thread_local! {
            static FILES: [(String, Format); 3] = [
                (head("ring.g2o", 40), Format::G2o),
                (head("w10000.graph", 40), Format::Toro),
                (head("manhattanolson3500_isam.txt", 40), Format::Isam),
            ];
        }
        FILES.with(|files| {
            for (text, format) in files {
                check_reader(&mutate(text, &edits), *format);
            }
        });
    }
}

/// A small saved map: the first 12 keyframes of Manhattan through the
/// engine, with an acknowledgement, a held edge and a GPS fix.
fn small_map() -> slamd::store::MapFile {
    use slamd::engine::{Engine, EngineConfig, FixInput};
    let g = slamd_tests::read("manhattanolson3500_g2oversion.g2o");
    let mut engine = Engine::new(EngineConfig::default());
    slamd_tests::feed(&mut engine, &g, 0..12);
    let position = slamd::gps::Geodetic::new(45.0, 9.0, 100.0).unwrap();
    let fix = FixInput {
        keyframe: 3,
        position,
        covariance: [4.0, 0.0, 0.0, 4.0],
        height_variance: Some(9.0),
    };
    engine.add_gps(fix).unwrap();
    engine.update();
    let mut map = engine.map();
    map.acks.push(slamd::store::AckState {
        frontend: 5,
        through: 40,
        beyond: vec![42],
    });
    let o = slamd_protocol::codec::Origin {
        frontend: 5,
        sequence: 42,
    };
    map.held.push(slamd::store::Record::Edge(o, g.edge_input(20)));
    map
}

/// The map file's head and body, and the same file with `body` in place
/// of its own and a checksum that matches it.
fn reframed(file: &[u8], body: &[u8]) -> Vec<u8> {
    let mut out = file[..24].to_vec();
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&crc32c::crc32c(body).to_le_bytes());
    out.extend_from_slice(body);
    out
}

/// A map that decodes is taken up by the engine or refused with a reason,
/// never a panic.
fn check_map(bytes: &[u8]) {
    use slamd::store::MapFile;
    let path = Path::new("fuzz.map");
    if let Ok(map) = MapFile::<Pose2>::decode(path, bytes) {
        let config = slamd::engine::EngineConfig {
            background: false,
            ..slamd::engine::EngineConfig::default()
        };
        let _ = map.graph();
        if let Err(e) = slamd::engine::Engine::restore(config, map, false) {
            assert!(!e.to_string().is_empty());
        }
    }
}

proptest! {
    #![proptest_config(config())]

    /// A saved map with bytes flipped or set (its checksum made to match,
    /// so the body's decoder and the engine see them), or cut short.
    #[test]
    fn maps_take_mutated_bytes(
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..8),
        cut in any::<usize>(),
    ) {
        thread_local! {
            static MAP: Vec<u8> = small_map().encode();
        }
        MAP.with(|file| {
            let mut body = file[32..].to_vec();
            for &(at, v) in &edits {
                let n = body.len();
                body[at % n] = v;
            }
            check_map(&reframed(file, &body));
            check_map(&file[..cut % file.len()]);
            let mut flipped = file.clone();
            let n = flipped.len();
            flipped[edits[0].0 % n] ^= 1 << (edits[0].1 % 8);
            prop_assert!(slamd::store::MapFile::<Pose2>::decode(Path::new("x"), &flipped).is_err() || flipped == *file);
            Ok(())
        })?;
    }

    /// Journal record payloads of arbitrary bytes, and journals of
    /// arbitrary bytes after a valid head: every record read is checked,
    /// the rest is cut with a reason.
    #[test]
    fn journals_take_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        if let Ok(slamd::store::Record::Edge(_, e)) = slamd::store::Record::<Pose2>::decode(&bytes) {
            prop_assert!(e.measurement.is_finite());
            prop_assert!(Information::from_upper(e.information.upper()).is_ok());
        }
        let dir = std::env::temp_dir().join(format!("slamd-fuzz-journal-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!("{:?}", std::thread::current().id()).replace(['(', ')'], ""));
        static HEAD: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
        let head = HEAD.get_or_init(|| {
            let never = slamd::store::SyncPolicy::Never;
            drop(slamd::store::Journal::create(&path, 0, never, std::time::Duration::ZERO).unwrap());
            std::fs::read(&path).unwrap()
        });
        let mut file = head.clone();
        file.extend_from_slice(&bytes);
        std::fs::write(&path, &file).unwrap();
        let read = slamd::store::recovery::read::<Pose2>(&path).unwrap().expect("the file is there");
        prop_assert!(read.valid_len as usize <= file.len());
        prop_assert_eq!(read.cut.is_some(), (read.valid_len as usize) < file.len());
    }
}
