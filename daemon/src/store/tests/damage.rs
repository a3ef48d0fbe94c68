//! A damaged journal refused and recovered; a damaged map taken up from
//! the checkpoint before it.

use super::*;

/// Damage in the middle of a journal, with whole records after it, is no
/// torn write: the directory is refused with the offset and the count of
/// records after it, and nothing on disk changes. `recover` then keeps
/// every other record, names the lost message, and keeps the file as it
/// was under a new name.
#[test]
fn a_damaged_record_with_whole_ones_after_it_is_refused_then_recovered() {
    for (what, damage) in [("flip", 1usize), ("zero", 16)] {
        let dir = temp_dir(&format!("damaged-{what}"));
        let records = stream(20);
        write_journal(&dir, &records);
        let path = dir.join("journal");
        let whole = std::fs::read(&path).unwrap();
        // inside the 10th record (keyframe 5), 29 whole ones after it
        let offsets = recovery::salvage::<Pose2>(&path).unwrap().unwrap().offsets;
        let at = offsets[9] as usize + 12;
        let mut bad = whole.clone();
        for b in &mut bad[at..at + damage] {
            *b = if damage == 1 { *b ^ 0x10 } else { 0 };
        }
        std::fs::write(&path, &bad).unwrap();
        let err = StateDir::open::<Pose2>(&dir, &StateConfig::default())
            .err()
            .expect("refused");
        assert!(
            matches!(&err, StoreError::Damaged { offset, following: 29, .. } if *offset == offsets[9]),
            "{what}: {err}"
        );
        assert!(err.to_string().contains("slamd recover --state"), "{err}");
        assert_eq!(std::fs::read(&path).unwrap(), bad, "{what}: the journal changed");

        let done = recovery::recover::<Pose2>(&dir).unwrap();
        assert_eq!((done.kept, done.damage.len()), (records.len() - 1, 1), "{what}");
        let lost = records[9].origin();
        assert_eq!(
            done.lost,
            vec![recovery::Lost {
                frontend: lost.frontend,
                first: lost.sequence,
                last: lost.sequence
            }]
        );
        assert_eq!(
            std::fs::read(done.moved_to.unwrap()).unwrap(),
            bad,
            "{what}: the old file kept"
        );
        let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
        let mut kept = records.clone();
        kept.remove(9);
        assert_eq!(rec.tail, kept, "{what}");
        assert!(rec.cut.is_none());
    }
}

/// A map that fails its checksum falls back to the checkpoint before it
/// and the two journals since, and the next checkpoint replaces it (the
/// damaged file kept aside). Without a whole previous checkpoint the
/// directory is refused.
#[test]
fn a_damaged_map_falls_back_to_the_checkpoint_before_it() {
    let dir = temp_dir("fallback");
    let records = stream(12);
    let (first, rest) = records.split_at(9);
    let (second, third) = rest.split_at(10);
    let (mut state, _) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    for (part, keyframes) in [(first, 5), (second, 10)] {
        for r in part {
            state.journal().append(r);
        }
        let mut map = sample_map();
        map.keyframes.truncate(1);
        map.keyframes[0].id = keyframes;
        state.checkpoint(map).unwrap();
    }
    for r in third {
        state.journal().append(r);
    }
    state.journal().commit().unwrap();
    drop(state);

    let path = dir.join("map");
    let mut bad = std::fs::read(&path).unwrap();
    let at = bad.len() / 2;
    bad[at] ^= 1;
    std::fs::write(&path, &bad).unwrap();
    let (mut state, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    let map = rec.map.expect("the checkpoint before");
    assert_eq!((map.generation, map.keyframes[0].id), (1, 5));
    assert_eq!(rec.tail[..], rest[..], "the journals after it");
    assert_eq!(std::fs::read(&path).unwrap(), bad, "nothing changed yet");

    let mut next = sample_map();
    next.keyframes.truncate(1);
    next.keyframes[0].id = 12;
    state.checkpoint(next).unwrap();
    drop(state);
    let kept: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("map.damaged-"))
        .collect();
    assert_eq!(kept.len(), 1);
    assert_eq!(std::fs::read(kept[0].path()).unwrap(), bad);
    let (_, rec) = StateDir::open::<Pose2>(&dir, &StateConfig::default()).unwrap();
    let map = rec.map.unwrap();
    assert_eq!((map.generation, map.keyframes[0].id, rec.tail.len()), (3, 12, 0));

    // no whole checkpoint before it: refused, unchanged
    std::fs::write(&path, &bad).unwrap();
    std::fs::remove_file(dir.join("map.prev")).unwrap();
    let err = StateDir::open::<Pose2>(&dir, &StateConfig::default())
        .err()
        .expect("refused");
    assert!(err.to_string().contains("checksum"), "{err}");
    assert_eq!(std::fs::read(&path).unwrap(), bad);
}
