//! A state directory whose journal or map is damaged anywhere: never a
//! panic; damage with whole records after it refuses the directory and
//! changes no byte; `slamd recover` then keeps every record but the
//! damaged ones, names each message lost, and the map the records make
//! once those are sent again is the whole graph, at its optimum.
//!
//! The directory holds Manhattan: a checkpoint of its first 1,750
//! keyframes and a journal of the rest, as a frontend sent them (keyframe,
//! then its edges, numbered in order). Damage lands at every 997th byte of
//! each file: one byte flipped, and separately 16 bytes zeroed.

use slamd::geometry::Pose2;
use slamd::graph::KeyframeInput;
use slamd::store::recovery::{self, Lost};
use slamd::store::{MapFile, Record, StateConfig, StateDir, StoreError};
use slamd_protocol::codec::Origin;
use slamd_tests::{fresh_dir, optimum, read, slamd_bin};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

const FRONTEND: u32 = 7;

/// The checkpoint and the journal's records, as written.
fn manhattan(dir: &Path) -> Vec<Record> {
    let g = read("manhattanolson3500_g2oversion.g2o");
    let half = 1750;
    let prefix = g.prefix(half);
    let mut map = MapFile::solved(&prefix, &optimum(&prefix).poses);
    let groups = g.by_newer();
    let mut sequence = 0;
    let mut records = Vec::new();
    let mut next = || {
        sequence += 1;
        Origin {
            frontend: FRONTEND,
            sequence,
        }
    };
    // the frontend numbered the checkpoint's messages too
    for (k, group) in groups.iter().enumerate() {
        let origin = next();
        let edges = group.iter().map(|&e| (next(), e)).collect::<Vec<_>>();
        if k >= half {
            records.push(Record::Keyframe(origin, KeyframeInput::new(g.id_of(k), None, 0)));
            records.extend(edges.into_iter().map(|(o, e)| Record::Edge(o, g.edge_input(e))));
        }
    }
    // the checkpoint took every message before the journal's first
    map.acks = vec![slamd::store::AckState {
        frontend: FRONTEND,
        through: records[0].origin().sequence - 1,
        beyond: Vec::new(),
    }];
    let (mut state, _) = StateDir::open::<Pose2>(dir, &StateConfig::default()).expect("a new directory");
    state.checkpoint(map).expect("a checkpoint");
    for r in &records {
        state.journal().append(r);
    }
    state.journal().commit().expect("the journal written");
    records
}

/// Every damaged copy of `file` this test makes: at every 997th byte, one
/// byte flipped, and separately 16 bytes zeroed (those that change it).
fn damaged(file: &[u8]) -> impl Iterator<Item = (&'static str, usize, usize, Vec<u8>)> + '_ {
    [("flip", 1usize), ("zero", 16)]
        .into_iter()
        .flat_map(move |(what, width)| {
            (0..file.len()).step_by(997).filter_map(move |at| {
                let mut bad = file.to_vec();
                let end = (at + width).min(bad.len());
                for b in &mut bad[at..end] {
                    *b = if width == 1 { *b ^ 0x5a } else { 0 };
                }
                (bad != file).then_some((what, width, at, bad))
            })
        })
}

/// The records `recovered` lacks of `sent`, by message number, and
/// whether each of them lies in a reported range.
fn missing(sent: &[Record], recovered: &[Record], lost: &[Lost]) -> Vec<(u64, bool)> {
    let have: std::collections::BTreeSet<u64> = recovered.iter().map(|r| r.origin().sequence).collect();
    sent.iter()
        .map(|r| r.origin().sequence)
        .filter(|s| !have.contains(s))
        .map(|s| {
            (
                s,
                lost.iter()
                    .any(|l| l.frontend == FRONTEND && (l.first..=l.last).contains(&s)),
            )
        })
        .collect()
}

#[test]
fn damage_anywhere_is_refused_unchanged_and_recovered_to_the_whole_graph() {
    let clean = fresh_dir("corruption-clean");
    let sent = manhattan(&clean);
    let journal = std::fs::read(clean.join("journal")).unwrap();
    let map = std::fs::read(clean.join("map")).unwrap();
    let offsets = recovery::salvage::<Pose2>(&clean.join("journal"))
        .unwrap()
        .unwrap()
        .offsets;
    let last_record = *offsets.last().unwrap() as usize;
    let dir = fresh_dir("corruption-damaged");
    let (mut cases, mut refused, mut torn, mut head) = (0, 0, 0, 0);
    for (what, width, at, bad) in damaged(&journal) {
        cases += 1;
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("map"), &map).unwrap();
        std::fs::write(dir.join("journal"), &bad).unwrap();
        match StateDir::open::<Pose2>(&dir, &StateConfig::default()) {
            Ok((_, rec)) => {
                // only the last record damaged: a torn tail, cut
                assert!(at >= last_record, "{what} at {at}: read as a torn tail");
                assert_eq!(rec.tail[..], sent[..sent.len() - 1], "{what} at {at}");
                torn += 1;
                continue;
            }
            Err(StoreError::Damaged {
                offset, following, ..
            }) => {
                assert!((offset as usize) < at + width && following > 0, "{what} at {at}");
                refused += 1;
            }
            Err(e) if at < 24 => {
                // the head: its magic, version or checksum refuses the file
                let refused_whole = matches!(
                    e,
                    StoreError::NotOurs { .. } | StoreError::Version { .. } | StoreError::Corrupt { .. }
                );
                assert!(refused_whole, "{what} at {at}: {e}");
                assert_eq!(std::fs::read(dir.join("journal")).unwrap(), bad, "{what} at {at}");
                head += 1;
                continue;
            }
            Err(e) => panic!("{what} at {at}: {e}"),
        }
        assert_eq!(
            std::fs::read(dir.join("journal")).unwrap(),
            bad,
            "{what} at {at}: changed"
        );
        assert_eq!(
            std::fs::read(dir.join("map")).unwrap(),
            map,
            "{what} at {at}: map changed"
        );

        let done = recovery::recover::<Pose2>(&dir).unwrap();
        let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).expect("recovered");
        let gone = missing(&sent, &rec.tail, &done.lost);
        // a flipped byte loses its record, 16 zeroed bytes at most two
        assert!(
            !gone.is_empty() && gone.len() <= width.min(2),
            "{what} at {at}: lost {gone:?}"
        );
        assert!(
            gone.iter().all(|&(_, named)| named),
            "{what} at {at}: unreported {gone:?}"
        );
        assert_eq!(done.kept, sent.len() - gone.len());
    }
    // every offset but the head's and the last record's is corruption
    assert_eq!(cases, refused + torn + head);
    assert!(
        torn <= 2 && head <= 2 && refused >= 700,
        "{refused} refused, {torn} torn, {head} heads"
    );
}

/// The directory's first checkpoint, so no earlier one to fall back to
/// (`store::tests::damage` has the fall-back).
#[test]
fn a_damaged_map_is_refused_unchanged() {
    let clean = fresh_dir("corruption-map-clean");
    manhattan(&clean);
    let map = std::fs::read(clean.join("map")).unwrap();
    let journal = std::fs::read(clean.join("journal")).unwrap();
    let dir = fresh_dir("corruption-map-damaged");
    for (what, _, at, bad) in damaged(&map) {
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("map"), &bad).unwrap();
        std::fs::write(dir.join("journal"), &journal).unwrap();
        let err = StateDir::open::<Pose2>(&dir, &StateConfig::default()).err();
        let err = err.unwrap_or_else(|| panic!("{what} at {at}: a damaged map was taken"));
        let named = match &err {
            StoreError::Corrupt { path, .. }
            | StoreError::NotOurs { path, .. }
            | StoreError::Version { path, .. } => path.clone(),
            other => panic!("{what} at {at}: {other}"),
        };
        assert_eq!(named, dir.join("map"), "{what} at {at}");
        assert_eq!(std::fs::read(dir.join("map")).unwrap(), bad, "{what} at {at}");
        assert_eq!(
            std::fs::read(dir.join("journal")).unwrap(),
            journal,
            "{what} at {at}"
        );
    }
}

/// Through the binary: the daemon refuses the directory naming the file,
/// the offset and the records after it; `slamd recover` reports what it
/// kept and lost; the records it kept and the lost ones sent again make
/// Manhattan's whole graph, which solves to its optimum.
#[test]
fn the_daemon_refuses_and_slamd_recover_reports() {
    let dir = fresh_dir("corruption-binary");
    let sent = manhattan(&dir);
    let path = dir.join("journal");
    let offsets = recovery::salvage::<Pose2>(&path).unwrap().unwrap().offsets;
    let mut bad = std::fs::read(&path).unwrap();
    let at = offsets[offsets.len() / 2] as usize + 10;
    bad[at] ^= 0xff;
    std::fs::write(&path, &bad).unwrap();
    let out = Command::new(slamd_bin())
        .args([
            "run",
            "--namespace",
            &format!("slamd-test-{}-corrupt", std::process::id()),
        ])
        .args(["--state", dir.to_str().unwrap()])
        .env("SLAMD_LOG", "error")
        .output()
        .expect("slamd run");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let following = sent.len() - offsets.len() / 2 - 1;
    let expected = format!(
        "the record at byte {} is damaged (checksum mismatch) and {following} whole records follow it",
        offsets[offsets.len() / 2]
    );
    assert!(stderr.contains(&expected), "{stderr}");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        bad,
        "slamd run changed the journal"
    );

    let out = Command::new(slamd_bin())
        .args(["recover", "--state", dir.to_str().unwrap()])
        .output()
        .expect("slamd recover");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let lost = sent[offsets.len() / 2].origin().sequence;
    assert!(
        stdout.contains(&format!("kept {} records", sent.len() - 1)),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!("lost: frontend {FRONTEND} messages {lost}..={lost}")),
        "{stdout}"
    );

    // the kept records and the lost one sent again: the whole graph
    let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).expect("recovered");
    let mut by_number: BTreeMap<u64, Record> = rec.tail.iter().map(|r| (r.origin().sequence, *r)).collect();
    by_number.insert(lost, sent[offsets.len() / 2]);
    let map = rec.map.expect("the checkpoint");
    let mut g = map.graph().expect("the checkpoint's graph");
    for r in by_number.values() {
        match *r {
            Record::Keyframe(_, k) => {
                g.add_keyframe(k.id, k.guess).expect("a new keyframe");
            }
            Record::Edge(_, e) => {
                g.add_edge(e.from, e.to, e.measurement, e.information, e.kind)
                    .expect("a valid edge");
            }
            _ => unreachable!("the stream holds keyframes and edges"),
        }
    }
    let whole = read("manhattanolson3500_g2oversion.g2o");
    assert_eq!((g.len(), g.edges().len()), (whole.len(), whole.edges().len()));
    let chi2 = optimum(&g).chi2;
    assert!((chi2 - 146.077).abs() < 1e-3, "χ² {chi2}");
}
