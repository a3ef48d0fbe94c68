//! Reading a journal back: a torn tail told from corruption, and every
//! record that can be verified kept.
//!
//! A torn write can damage only the last record, so a damaged record with
//! nothing whole after it is cut off ([`Cut`]), as the daemon always did.
//! A damaged record with whole records after it is corruption: [`read`]
//! refuses the file with the offset and how many whole records follow
//! ([`StoreError::Damaged`]), and [`salvage`] resynchronises past it, at
//! the next offset where a frame's length and CRC-32C hold and its payload
//! decodes, keeping every record it can verify and naming each damaged
//! stretch ([`Damage`]).

use super::bytes::{unframe, Framed};
use super::journal::{check_head, HEAD, MAGIC};
use super::map::MapFile;
use super::record::Record;
use super::StoreError;
use slamd_types::{Pose2, RigidMotion};
use std::path::Path;

/// Where a journal's readable part ended and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cut {
    /// The byte offset of the first record left out.
    pub offset: u64,
    /// Why it was left out.
    pub reason: String,
}

/// A damaged stretch of a journal with whole records after it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Damage {
    /// Where it starts.
    pub offset: u64,
    /// Its length in bytes, up to the next whole record.
    pub len: u64,
    /// What is wrong with its first record.
    pub reason: String,
}

/// What [`read`] found.
#[derive(Debug)]
pub struct Contents<P: RigidMotion = Pose2> {
    /// The map generation the journal follows.
    pub generation: u64,
    /// The format version its head names.
    pub version: u32,
    /// Its whole, checked records, in order.
    pub records: Vec<Record<P>>,
    /// Bytes that hold them (the head included).
    pub valid_len: u64,
    /// Set when the file went on past them: a torn tail, cut there.
    pub cut: Option<Cut>,
}

/// What [`salvage`] found: every record that can be verified, and what
/// could not.
#[derive(Debug)]
pub struct Salvage<P: RigidMotion = Pose2> {
    /// The whole records, their damaged stretches skipped, and the tail.
    pub contents: Contents<P>,
    /// The damaged stretches with whole records after them.
    pub damage: Vec<Damage>,
    /// Where each record starts.
    pub offsets: Vec<u64>,
}

impl<P: RigidMotion> Salvage<P> {
    /// How many of the records start before `offset`.
    pub fn before(&self, offset: u64) -> usize {
        self.offsets.partition_point(|&o| o < offset)
    }
}

/// The longest payload a record frame has (a 3-D edge's is 254 bytes): a
/// frame that claims more is not one, which bounds the search for the
/// next record past a damaged one.
const MAX_RECORD: usize = 1024;

/// Whether a whole record of `P` starts at the front of `bytes`, and its
/// length; an error only for a record of the other dimension.
fn whole_record<P: RigidMotion>(bytes: &[u8]) -> Result<Result<(Record<P>, usize), String>, StoreError> {
    let claimed = bytes
        .get(..4)
        .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    if claimed as usize > MAX_RECORD {
        return Ok(Err(format!(
            "a length of {claimed} bytes, longer than any record"
        )));
    }
    match unframe(bytes) {
        Framed::Whole(payload, used) => match Record::decode(payload) {
            Ok(r) => Ok(Ok((r, used))),
            Err(e @ StoreError::Dimension { .. }) => Err(e),
            Err(e) => Ok(Err(e.to_string())),
        },
        Framed::Torn => Ok(Err("torn (the file ends inside it)".into())),
        Framed::Corrupt => Ok(Err("checksum mismatch".into())),
    }
}

/// Reads every frame after the head of a journal of `generation` and
/// `version`, resynchronising past a damaged one at the next offset where
/// a whole record starts (by its length and checksum). Damage with no
/// whole record after it is a torn tail.
fn scan<P: RigidMotion>(bytes: &[u8], generation: u64, version: u32) -> Result<Salvage<P>, StoreError> {
    let mut out = Salvage {
        contents: Contents {
            generation,
            version,
            records: Vec::new(),
            valid_len: HEAD as u64,
            cut: None,
        },
        damage: Vec::new(),
        offsets: Vec::new(),
    };
    let mut at = HEAD;
    while at < bytes.len() {
        let reason = match whole_record::<P>(&bytes[at..])? {
            Ok((r, used)) => {
                out.offsets.push(at as u64);
                out.contents.records.push(r.of_version(version));
                at += used;
                out.contents.valid_len = at as u64;
                continue;
            }
            Err(reason) => reason,
        };
        let mut next = None;
        for p in at + 1..bytes.len() {
            if whole_record::<P>(&bytes[p..])?.is_ok() {
                next = Some(p);
                break;
            }
        }
        let offset = at as u64;
        match next {
            Some(p) => {
                out.damage.push(Damage {
                    offset,
                    len: (p - at) as u64,
                    reason,
                });
                at = p;
            }
            None => {
                out.contents.cut = Some(Cut { offset, reason });
                break;
            }
        }
    }
    Ok(out)
}

/// The file's bytes and its head's generation and version; `None` when
/// there is no file.
fn open_file(path: &Path) -> Result<Option<(Vec<u8>, u64, u32)>, StoreError> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(StoreError::io("read", path, e)),
    };
    let (generation, version) = check_head(path, &bytes, MAGIC, "journal")?;
    Ok(Some((bytes, generation, version)))
}

/// Reads a journal: every record, and a torn tail (a last record that is
/// damaged, with nothing whole after it) to cut off. A damaged record
/// with whole ones after it is no torn write but corruption: an error
/// naming the offset and how many whole records follow
/// ([`StoreError::Damaged`]), the file untouched. `Ok(None)` when there
/// is no file; an error when a record is of the other dimension than
/// `P`'s (a daemon started on another dimension's directory must not cut
/// it).
pub fn read<P: RigidMotion>(path: &Path) -> Result<Option<Contents<P>>, StoreError> {
    let Some(salvage) = salvage(path)? else {
        return Ok(None);
    };
    if let Some(first) = salvage.damage.first() {
        let records = &salvage.contents.records;
        return Err(StoreError::Damaged {
            path: path.to_path_buf(),
            offset: first.offset,
            reason: first.reason.clone(),
            following: records.len() - salvage.before(first.offset),
        });
    }
    Ok(Some(salvage.contents))
}

/// Reads a journal keeping every record it can verify: past a damaged
/// record it resynchronises at the next whole one (by length and
/// checksum) and reports the stretch it skipped.
pub fn salvage<P: RigidMotion>(path: &Path) -> Result<Option<Salvage<P>>, StoreError> {
    let Some((bytes, generation, version)) = open_file(path)? else {
        return Ok(None);
    };
    scan::<P>(&bytes, generation, version).map(Some)
}

/// Message numbers of one frontend that a damaged stretch held, told by
/// the whole records on either side of it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Lost {
    /// The frontend.
    pub frontend: u32,
    /// The first number missing.
    pub first: u64,
    /// The last number missing.
    pub last: u64,
}

/// The checkpoint before the current one and the records of the journal
/// that followed it (`map.prev`, `journal.prev`), when both are whole and
/// of the same generation: what a map that fails its checksum falls back
/// to, with the current journal after them.
pub fn previous_checkpoint<P: RigidMotion>(dir: &Path) -> Option<(MapFile<P>, Vec<Record<P>>)> {
    let map_path = dir.join("map.prev");
    // a missing or damaged copy is no fall-back: the map's own error is the one to tell
    let map = MapFile::<P>::read(&map_path).ok()?;
    match read::<P>(&dir.join("journal.prev")) {
        Ok(Some(j)) if j.generation == map.generation && j.cut.is_none() => Some((map, j.records)),
        _ => None,
    }
}

/// What [`recover`] did to a state directory's journal.
#[derive(Debug)]
pub struct Recovery {
    /// Records kept.
    pub kept: usize,
    /// The stretches left out: damaged ones with whole records after them,
    /// then a torn tail, if any.
    pub damage: Vec<Damage>,
    /// The message numbers the damaged stretches held.
    pub lost: Vec<Lost>,
    /// Where the journal as it was now lies, when anything was left out.
    pub moved_to: Option<std::path::PathBuf>,
}

/// Keeps every record of `dir`'s journal that can be verified: the file
/// as it was is kept under a new name (`journal.damaged-SECONDS`, never
/// deleted) and a journal of the verified records, in this version's
/// format, takes its place atomically. Takes the directory's lock, so no
/// daemon may be running on it. A journal with nothing damaged is left
/// as it is.
pub fn recover<P: RigidMotion>(dir: &Path) -> Result<Recovery, StoreError> {
    let _lock = super::lock(dir)?;
    let path = dir.join("journal");
    let Some(salvage) = salvage::<P>(&path)? else {
        return Ok(Recovery {
            kept: 0,
            damage: Vec::new(),
            lost: Vec::new(),
            moved_to: None,
        });
    };
    let mut damage = salvage.damage.clone();
    if let Some(cut) = &salvage.contents.cut {
        let len = std::fs::metadata(&path)
            .map_err(|e| StoreError::io("read", &path, e))?
            .len();
        damage.push(Damage {
            offset: cut.offset,
            len: len - cut.offset,
            reason: cut.reason.clone(),
        });
    }
    let lost = salvage.damage.iter().flat_map(|d| salvage.lost_in(d)).collect();
    let contents = &salvage.contents;
    if damage.is_empty() {
        return Ok(Recovery {
            kept: contents.records.len(),
            damage,
            lost,
            moved_to: None,
        });
    }
    let aside = aside_name(dir, "journal.damaged")?;
    super::keep(&path, &aside)?;
    let policy = super::SyncPolicy::Always;
    drop(super::Journal::rewrite(
        &path,
        contents.generation,
        &contents.records,
        policy,
        std::time::Duration::ZERO,
    )?);
    Ok(Recovery {
        kept: contents.records.len(),
        damage,
        lost,
        moved_to: Some(aside),
    })
}

/// `STEM-SECONDS` in `dir`, with `-N` added if that is taken.
pub(super) fn aside_name(dir: &Path, stem: &str) -> Result<std::path::PathBuf, StoreError> {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let base = format!("{stem}-{secs}");
    (0..1000)
        .map(|n| {
            dir.join(if n == 0 {
                base.clone()
            } else {
                format!("{base}-{n}")
            })
        })
        .find(|p| !p.exists())
        .ok_or_else(|| StoreError::io("name a copy in", dir, std::io::ErrorKind::AlreadyExists.into()))
}

impl<P: RigidMotion> Salvage<P> {
    /// The message numbers `damage` held, per frontend whose records stand
    /// on both sides of it: those between the last number before it and
    /// the first after it.
    fn lost_in(&self, damage: &Damage) -> Vec<Lost> {
        use std::collections::BTreeMap;
        let records = &self.contents.records;
        let (before, after) = (
            self.before(damage.offset),
            self.before(damage.offset + damage.len),
        );
        let mut last = BTreeMap::new();
        for r in &records[..before] {
            let o = r.origin();
            let e = last.entry(o.frontend).or_insert(o.sequence);
            *e = (*e).max(o.sequence);
        }
        let mut first = BTreeMap::new();
        for r in &records[after..] {
            let o = r.origin();
            let e = first.entry(o.frontend).or_insert(o.sequence);
            *e = (*e).min(o.sequence);
        }
        last.into_iter()
            .filter_map(|(frontend, l)| {
                let (f, next) = (*first.get(&frontend)?, l.checked_add(1)?);
                (f > next).then_some(Lost {
                    frontend,
                    first: next,
                    last: f - 1,
                })
            })
            .collect()
    }
}
