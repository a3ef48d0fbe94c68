use super::*;
use crate::gps::Georef;
use faer::c64;
use slamd_protocol::codec::Origin;
use slamd_types::{
    EdgeInput, EdgeKind, FixInput, Geodetic, Information, Information6, KeyframeInput, Pose2, Pose3,
};

fn origin(s: u64) -> Origin {
    Origin {
        frontend: 3,
        sequence: s,
    }
}

/// Keyframes 0..n with odometry between them, as a frontend sends them.
fn stream(n: u64) -> Vec<Record> {
    let mut out = Vec::new();
    let mut s = 0;
    for k in 0..n {
        s += 1;
        out.push(Record::Keyframe(origin(s), KeyframeInput::new(k, None, 0)));
        if k > 0 {
            s += 1;
            let step = Pose2::new(1.0, 0.0, 0.1);
            let e = EdgeInput::new(k - 1, k, step, Information::identity(), EdgeKind::Odometry);
            out.push(Record::Edge(origin(s), e));
        }
    }
    out
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("slamd-store-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn write_journal(dir: &Path, records: &[Record]) {
    let (mut state, _) = StateDir::open::<Pose2>(dir, &StateConfig::default()).unwrap();
    for r in records {
        state.journal().append(r);
    }
    state.journal().commit().unwrap();
}

#[test]
fn the_journal_reads_back_what_was_committed() {
    let dir = temp_dir("roundtrip");
    let records = stream(20);
    write_journal(&dir, &records);
    let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    assert_eq!(rec.tail, records);
    assert!(rec.cut.is_none() && rec.map.is_none());
}

/// A journal of the previous format is rewritten in this one before
/// anything is appended, records kept, so an older slamd reading it back
/// refuses it by its version rather than cutting the new records.
#[test]
fn an_older_journal_is_rewritten_in_this_format_before_appending() {
    let dir = temp_dir("upgrade");
    let records = stream(6);
    write_journal(&dir, &records);
    let path = dir.join("journal");
    let mut bytes = std::fs::read(&path).unwrap();
    let generation = u64::from_le_bytes(bytes[16..24].try_into().unwrap());
    bytes[..journal::HEAD].copy_from_slice(&old_head(journal::MAGIC, 2, generation));
    std::fs::write(&path, &bytes).unwrap();
    let (mut state, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    assert_eq!(rec.tail, records);
    let stamped = Record::Keyframe(origin(99), KeyframeInput::new(99, None, 123));
    state.journal().append(&stamped);
    state.journal().commit().unwrap();
    let after = std::fs::read(&path).unwrap();
    assert_eq!(
        u32::from_le_bytes(after[8..12].try_into().unwrap()),
        FORMAT_VERSION
    );
    let back = recovery::read::<Pose2>(&path).unwrap().unwrap();
    assert_eq!(back.records[..records.len()], records[..]);
    assert_eq!(back.records.last(), Some(&stamped));
}

/// A loop closure written newer-id-first, with anisotropic information.
fn newer_first_loop_closure(s: u64) -> Record {
    let info = Information::from_upper([1e4, 0.0, 0.0, 1.0, 0.0, 50.0]).unwrap();
    let z = Pose2::new(-4.0, 1.0, -std::f64::consts::FRAC_PI_2);
    Record::Edge(origin(s), EdgeInput::new(5, 1, z, info, EdgeKind::LoopClosure))
}

/// Until format version 4 slamd solved an edge written newer-id-first,
/// `(i, j, Z, Ω)`, as `(j, i, Z⁻¹, Ω)`. An older journal goes on meaning
/// that graph: its newer-first edges are read turned, and the rewrite
/// keeps them so; a journal of this version keeps them as written.
#[test]
fn an_older_journal_keeps_the_meaning_it_was_solved_with() {
    let dir = temp_dir("edge-meaning");
    let mut records = stream(6);
    records.push(newer_first_loop_closure(100));
    write_journal(&dir, &records);
    let path = dir.join("journal");
    let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    assert_eq!(rec.tail, records, "this version's journal keeps edges as written");
    drop(rec);
    let mut bytes = std::fs::read(&path).unwrap();
    let generation = u64::from_le_bytes(bytes[16..24].try_into().unwrap());
    bytes[..journal::HEAD].copy_from_slice(&old_head(journal::MAGIC, 3, generation));
    std::fs::write(&path, &bytes).unwrap();

    let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    let Some(&Record::Edge(o, written)) = records.last() else {
        unreachable!()
    };
    let Some(&Record::Edge(o2, read)) = rec.tail.last() else {
        panic!("no edge read back")
    };
    assert_eq!((o2, read.from, read.to, read.kind), (o, 1, 5, written.kind));
    assert_eq!(read.information, written.information, "the old meaning kept Ω");
    assert!(read
        .measurement
        .compose(&written.measurement)
        .to_array()
        .iter()
        .all(|v| v.abs() < 1e-15));
    assert_eq!(rec.tail[..records.len() - 1], records[..records.len() - 1]);
    // rewritten in this version, where the turned edge means the same
    let back = recovery::read::<Pose2>(&path).unwrap().unwrap();
    assert_eq!(back.version, FORMAT_VERSION);
    assert_eq!(back.records, rec.tail);
}

/// The journal cut at every byte offset inside its last record: the
/// daemon restarts with every record before it, the cut one is gone, and
/// appending afterwards yields a journal that reads whole.
#[test]
fn a_torn_last_record_is_cut_at_every_offset_and_only_it_is_lost() {
    let dir = temp_dir("torn");
    let records = stream(4);
    write_journal(&dir, &records);
    let path = dir.join("journal");
    let whole = std::fs::read(&path).unwrap();
    let mut last = bytes::Put::default();
    records[records.len() - 1].encode(&mut last);
    let last_start = whole.len() - bytes::FRAME_HEAD - last.0.len();
    assert!(last_start < whole.len());
    for cut in last_start..whole.len() {
        std::fs::write(&path, &whole[..cut]).unwrap();
        let (mut state, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
        assert_eq!(rec.tail, records[..records.len() - 1], "cut at {cut}");
        if cut > last_start {
            assert_eq!(
                rec.cut.as_ref().map(|c| c.offset),
                Some(last_start as u64),
                "cut at {cut}"
            );
        } else {
            assert!(rec.cut.is_none());
        }
        // the torn bytes are gone: a new record follows the last whole one
        let extra = Record::Refused(origin(99));
        state.journal().append(&extra);
        state.journal().commit().unwrap();
        drop(state);
        let (_, again) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
        let mut expected = records[..records.len() - 1].to_vec();
        expected.push(extra);
        assert_eq!(again.tail, expected, "cut at {cut}");
        assert!(again.cut.is_none());
    }
}

#[test]
fn a_corrupt_record_ends_the_journal_there() {
    let dir = temp_dir("corrupt");
    let records = stream(5);
    write_journal(&dir, &records);
    let path = dir.join("journal");
    let mut bytes = std::fs::read(&path).unwrap();
    let n = bytes.len();
    bytes[n - 3] ^= 0x40;
    std::fs::write(&path, &bytes).unwrap();
    let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    assert_eq!(rec.tail, records[..records.len() - 1]);
    assert!(rec.cut.unwrap().reason.contains("checksum"));
}

#[test]
fn another_format_version_is_refused_not_misread() {
    let dir = temp_dir("version");
    write_journal(&dir, &stream(2));
    let path = dir.join("journal");
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let err = StateDir::open::<Pose2>(&dir, &StateConfig::default())
        .err()
        .unwrap();
    assert!(matches!(err, StoreError::Version { found, .. } if found == FORMAT_VERSION + 1));
    assert!(
        err.to_string()
            .contains(&format!("format version {}", FORMAT_VERSION + 1)),
        "{err}"
    );
    bytes[8..12].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes[20] ^= 1;
    std::fs::write(&path, &bytes).unwrap();
    let err = StateDir::open::<Pose2>(&dir, &StateConfig::default())
        .err()
        .unwrap();
    assert!(err.to_string().contains("head is damaged"), "{err}");
    std::fs::write(&path, b"VERTEX_SE2 0 0 0 0\n").unwrap();
    let err = StateDir::open::<Pose2>(&dir, &StateConfig::default())
        .err()
        .unwrap();
    assert!(err.to_string().contains("not a slamd journal"), "{err}");
}

fn sample_map() -> MapFile {
    let info = Information::from_upper([10.0, 1.0, 0.0, 20.0, 0.5, 30.0]).unwrap();
    MapFile {
        generation: 0,
        keyframes: vec![
            MapKeyframe {
                id: 4,
                guess: None,
                estimate: Pose2::IDENTITY,
                lin: Pose2::IDENTITY,
                joined: true,
                timestamp_ns: 0,
            },
            MapKeyframe {
                id: 9,
                guess: Some(Pose2::new(1.0, 2.0, 0.3)),
                estimate: Pose2::new(1.1, 2.1, 0.31),
                lin: Pose2::new(1.05, 2.05, 0.305),
                joined: true,
                timestamp_ns: 1_700_000_000_000_000_009,
            },
        ],
        edges: vec![MapEdge {
            edge: EdgeInput::new(4, 9, Pose2::new(1.0, 2.0, 0.3), info, EdgeKind::LoopClosure),
            scale: 1.0,
            switch: 0.25,
            pending: false,
            origin: origin(2),
        }],
        origin: Some(Geodetic::new(45.0, 9.0, 100.0).unwrap()),
        georef: Some(SavedGeoref {
            georef: Georef {
                rotation: c64::new(0.6, 0.8),
                translation: c64::new(-3.0, 4.0),
                up: 2.5,
            },
            weight: 0.5,
        }),
        fixes: vec![FixInput {
            keyframe: 9,
            position: Geodetic::new(45.00001, 9.00001, 101.0).unwrap(),
            covariance: [4.0, 0.0, 0.0, 4.0],
            height_variance: Some(9.0),
        }],
        acks: vec![AckState {
            frontend: 3,
            through: 2,
            beyond: vec![5, 7],
        }],
        held: vec![Record::Edge(
            origin(6),
            EdgeInput::new(
                9,
                12,
                Pose2::IDENTITY,
                Information::identity(),
                EdgeKind::Odometry,
            ),
        )],
    }
}

#[test]
fn a_map_reads_back_and_a_damaged_one_is_refused() {
    let map = sample_map();
    let bytes = map.encode();
    let path = Path::new("sample.map");
    assert_eq!(MapFile::decode(path, &bytes).unwrap(), map);
    for cut in [0, 10, 24, 30, bytes.len() - 1] {
        assert!(
            MapFile::<Pose2>::decode(path, &bytes[..cut]).is_err(),
            "cut at {cut}"
        );
    }
    let mut bad = bytes.clone();
    bad[40] ^= 1;
    let err = MapFile::<Pose2>::decode(path, &bad).unwrap_err();
    assert!(err.to_string().contains("checksum"), "{err}");
}

#[test]
fn a_checkpoint_replaces_the_journal_and_a_stale_journal_is_dropped() {
    let dir = temp_dir("checkpoint");
    let records = stream(3);
    write_journal(&dir, &records);
    let old_journal = std::fs::read(dir.join("journal")).unwrap();
    {
        let (mut state, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
        assert_eq!(rec.tail.len(), records.len());
        state.checkpoint(sample_map()).unwrap();
        let after = Record::<Pose2>::Refused(origin(50));
        state.journal().append(&after);
        state.journal().commit().unwrap();
    }
    let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    let map = rec.map.unwrap();
    assert_eq!(map.generation, 1);
    assert_eq!(map.keyframes, sample_map().keyframes);
    assert_eq!(rec.tail, vec![Record::Refused(origin(50))]);
    // a crash between the map's rename and the new journal's: the old
    // journal, already in the map, is not replayed
    std::fs::write(dir.join("journal"), &old_journal).unwrap();
    let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    assert!(rec.tail.is_empty() && rec.map.is_some());
    // a journal newer than its map: the map was lost
    std::fs::remove_file(dir.join("map")).unwrap();
    let err = StateDir::open::<Pose2>(&dir, &StateConfig::default())
        .err()
        .unwrap();
    assert!(
        matches!(err, StoreError::Mismatch { journal: 1, map: 0 }),
        "{err}"
    );
}

#[test]
fn a_second_daemon_cannot_take_the_directory() {
    let dir = temp_dir("lock");
    let (_first, _) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    let err = StateDir::open::<Pose2>(&dir, &StateConfig::default())
        .err()
        .unwrap();
    assert!(matches!(err, StoreError::Locked(_)), "{err}");
}

#[test]
fn a_directory_that_cannot_be_written_is_refused_at_start() {
    let err = StateDir::open::<Pose2>(Path::new("/proc/slamd-state"), &StateConfig::default())
        .err()
        .unwrap();
    assert!(err.to_string().contains("cannot create"), "{err}");
}

/// A file head naming format `version` (`magic | version | crc32c |
/// generation`), as an older slamd wrote it.
fn old_head(magic: &[u8; 8], version: u32, generation: u64) -> Vec<u8> {
    let mut head = magic.to_vec();
    head.extend_from_slice(&version.to_le_bytes());
    head.extend_from_slice(&journal::head_crc(magic, version, generation).to_le_bytes());
    head.extend_from_slice(&generation.to_le_bytes());
    head
}

/// A map file of format `version` whose body is `body`.
fn old_map_file(version: u32, generation: u64, body: &[u8]) -> Vec<u8> {
    let mut old = old_head(map::MAGIC, version, generation);
    bytes::frame(&mut old, body);
    old
}

/// A map keeps newer-first edges as written; one of format version 3
/// reads them turned, information kept, as the slamd that wrote it
/// solved them (its own edges were stored turned already; held edges
/// were not).
#[test]
fn a_pending_loop_closure_reads_back_pending_and_only_from_this_format() {
    let mut map = sample_map();
    map.edges[0].switch = 0.0;
    map.edges[0].pending = true;
    let bytes = map.encode();
    let path = Path::new("pending.map");
    assert_eq!(MapFile::decode(path, &bytes).unwrap(), map);
    // format 4 had no pending loop closures: its switch of −1 is damage
    let old = old_map_file(4, map.generation, &bytes[journal::HEAD + 8..]);
    let err = MapFile::<Pose2>::decode(path, &old).unwrap_err();
    assert!(err.to_string().contains("switch -1"), "{err}");
}

#[test]
fn a_version_3_map_reads_newer_first_edges_as_it_solved_them() {
    let mut map = sample_map();
    let Record::Edge(o, held) = newer_first_loop_closure(6) else {
        unreachable!()
    };
    map.held = vec![Record::Edge(o, held)];
    map.edges[0].edge = EdgeInput {
        from: 9,
        to: 4,
        ..map.edges[0].edge
    };
    let bytes = map.encode();
    let path = Path::new("v3.map");
    assert_eq!(MapFile::decode(path, &bytes).unwrap(), map, "as written");

    let old = old_map_file(3, map.generation, &bytes[journal::HEAD + 8..]);
    let read = MapFile::<Pose2>::decode(path, &old).unwrap();
    let e = read.edges[0].edge;
    assert_eq!(
        (e.from, e.to, e.information),
        (4, 9, map.edges[0].edge.information)
    );
    assert_eq!(e.measurement, map.edges[0].edge.measurement.inverse());
    let Record::Edge(_, h) = read.held[0] else {
        panic!("held edge lost")
    };
    assert_eq!((h.from, h.to, h.information), (1, 5, held.information));
    assert_eq!(h.measurement, held.measurement.inverse());
}

#[test]
fn a_version_2_map_reads_without_timestamps() {
    // version 2 had no keyframe timestamps at the end
    let mut map = sample_map();
    let bytes = map.encode();
    let body = &bytes[journal::HEAD + 8..bytes.len() - 8 * map.keyframes.len()];
    for k in &mut map.keyframes {
        k.timestamp_ns = 0;
    }
    let old = old_map_file(2, map.generation, body);
    assert_eq!(MapFile::<Pose2>::decode(Path::new("v2.map"), &old).unwrap(), map);
}

#[test]
fn a_version_1_map_reads_as_2d() {
    // version 1 had no dimension byte at the start, nor the georeference's
    // up, the fixes' height variances and the timestamps at the end
    let mut map = sample_map();
    let bytes = map.encode();
    let tail = 8 * (1 + map.fixes.len() + map.keyframes.len());
    let body = &bytes[journal::HEAD + 8 + 1..bytes.len() - tail];
    map.georef.as_mut().unwrap().georef.up = 0.0;
    map.fixes[0].height_variance = None;
    for k in &mut map.keyframes {
        k.timestamp_ns = 0;
    }
    let old = old_map_file(1, map.generation, body);
    let path = Path::new("old.map");
    assert_eq!(MapFile::<Pose2>::decode(path, &old).unwrap(), map);
    let err = MapFile::<Pose3>::decode(path, &old).unwrap_err();
    assert!(
        matches!(err, StoreError::Dimension { found: 2, serving: 3 }),
        "{err}"
    );
}

#[test]
fn a_3d_map_reads_back_and_a_2d_reader_refuses_it() {
    let z = Pose3::from_xyz_rpy([1.0, 2.0, 3.0, 0.1, 0.2, 0.3]);
    let map = MapFile::<Pose3> {
        keyframes: vec![
            MapKeyframe {
                id: 1,
                guess: None,
                estimate: Pose3::IDENTITY,
                lin: Pose3::IDENTITY,
                joined: true,
                timestamp_ns: 0,
            },
            MapKeyframe {
                id: 2,
                guess: Some(z),
                estimate: z,
                lin: z,
                joined: true,
                timestamp_ns: 0,
            },
        ],
        edges: vec![MapEdge {
            edge: EdgeInput::new(1, 2, z, Information6::identity(), EdgeKind::Odometry),
            scale: 1.0,
            switch: 1.0,
            pending: false,
            origin: origin(2),
        }],
        held: vec![Record::Keyframe(origin(3), KeyframeInput::new(7, Some(z), 5))],
        ..MapFile::default()
    };
    let bytes = map.encode();
    let path = Path::new("spatial.map");
    let back = MapFile::<Pose3>::decode(path, &bytes).unwrap();
    assert_eq!(back.keyframes.len(), 2);
    assert!((back.keyframes[1].estimate.translation - z.translation).norm() < 1e-15);
    assert!(back.keyframes[1].lin.rotation.angle_to(&z.rotation) < 1e-12);
    assert_eq!(back.edges[0].edge.information, Information6::identity());
    assert_eq!(back.held.len(), 1);
    let err = MapFile::<Pose2>::decode(path, &bytes).unwrap_err();
    assert!(
        matches!(err, StoreError::Dimension { found: 3, serving: 2 }),
        "{err}"
    );
    assert!(
        err.to_string().contains("a 3-D map where a 2-D one is expected"),
        "{err}"
    );
}

mod damage;
