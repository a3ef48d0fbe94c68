//! The state directory: a write-ahead journal of every message taken in
//! and a checkpoint of the whole map, so that a daemon that dies loses
//! nothing it acknowledged.
//!
//! - `journal`: [`Record`]s, each framed with its length and CRC-32C,
//!   appended in the order the engine applied them and written once per
//!   batch, before the snapshot that acknowledges them ([`Journal`]).
//! - `map`: the whole map ([`MapFile`]), written beside it, fsynced and
//!   renamed into place; each checkpoint bumps its generation and starts a
//!   new journal that names it. A journal naming an older generation was
//!   already folded into the map (a crash between the two renames) and is
//!   dropped.
//! - `map.prev`, `journal.prev`: the checkpoint before and the journal
//!   that followed it, kept by each checkpoint: a map that fails its
//!   checksum falls back to them and the current journal.
//! - `lock`: held (`flock`) while a daemon uses the directory.
//!
//! On start, [`StateDir::open`] reads both: the journal's records, a torn
//! last record cut off with a warning, and the map. A damaged record with
//! whole records after it is corruption: the directory is refused,
//! unchanged, until [`recovery::recover`] has kept what can be verified.
//! A file of another format version is refused, never misread. The
//! formats are in docs/state.md.

mod bytes;
pub mod journal;
pub mod map;
pub mod record;
pub mod recovery;

pub use journal::Journal;
pub use map::{AckState, MapEdge, MapFile, MapKeyframe, SavedGeoref};
pub use record::Record;
pub use recovery::{Cut, Damage};

use serde::{Deserialize, Serialize};
use slamd_types::{Pose2, RigidMotion};
use std::fmt;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The version of the journal and map formats this slamd writes. It reads
/// [`OLDEST_FORMAT`] up to this one and refuses any other. Version 2 added
/// 3-D maps: its map body starts with the dimension (version 1 maps are
/// 2-D), and 3-D journal records have tags of their own. Version 3 added
/// keyframe timestamps: journal records of their own for a keyframe with
/// one, and one `u64` per keyframe at the end of the map body. Version 4
/// keeps every edge as written; an older file's newer-id-first edges are
/// read in the meaning slamd gave them then (`record::edge_of_version`).
/// Version 5 marks in the map the loop closures the outlier filter had not
/// decided yet (a switch of −1), which a restart holds out again.
pub const FORMAT_VERSION: u32 = 5;

/// The oldest format version this slamd reads.
pub const OLDEST_FORMAT: u32 = 1;

/// When the journal is fsynced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SyncPolicy {
    /// After every batch, before its acknowledgement is published: an
    /// acknowledged message survives a crash of the machine.
    #[default]
    Always,
    /// At most every `sync_interval_ms`: a crash of the daemon loses
    /// nothing acknowledged, a crash of the machine up to one interval.
    Interval,
    /// Never (the OS writes back): a crash of the daemon loses nothing
    /// acknowledged, a crash of the machine can lose anything not yet
    /// written back.
    Never,
}

/// Why the state directory cannot be used.
#[derive(Debug)]
pub enum StoreError {
    /// A file operation failed.
    Io {
        /// What was being done.
        doing: &'static str,
        /// To which file.
        path: PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
    /// The file is not a slamd journal or map.
    NotOurs {
        /// The file.
        path: PathBuf,
        /// What it should have been.
        what: String,
    },
    /// The file is of another format version.
    Version {
        /// The file.
        path: PathBuf,
        /// Its version.
        found: u32,
    },
    /// A map file fails its checksum or does not decode.
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// A field does not decode (a record or a map body).
    Malformed(String),
    /// Another daemon holds the directory.
    Locked(PathBuf),
    /// The directory holds a map of the other dimension.
    Dimension {
        /// The map's dimension.
        found: u32,
        /// The daemon's.
        serving: u32,
    },
    /// The journal names a map generation the map file does not have.
    Mismatch {
        /// The journal's generation.
        journal: u64,
        /// The map's.
        map: u64,
    },
    /// A journal record is damaged and whole records follow it: not a
    /// torn write, which can damage only the last one.
    Damaged {
        /// The journal.
        path: PathBuf,
        /// Where the damaged record starts.
        offset: u64,
        /// What is wrong with it.
        reason: String,
        /// Whole records after it.
        following: usize,
    },
}

impl StoreError {
    pub(crate) fn io(doing: &'static str, path: &Path, error: std::io::Error) -> Self {
        StoreError::Io {
            doing,
            path: path.to_path_buf(),
            error,
        }
    }
}

impl fmt::Display for StoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StoreError::Io { doing, path, error } => write!(f, "cannot {doing} {}: {error}", path.display()),
            StoreError::NotOurs { path, what } => write!(f, "{} is not a slamd {what} file", path.display()),
            StoreError::Version { path, found } => write!(
                f,
                "{} is of format version {found}; this slamd reads versions {OLDEST_FORMAT} to {FORMAT_VERSION}",
                path.display()
            ),
            StoreError::Corrupt { path, why } => write!(f, "{} is corrupt: {why}", path.display()),
            StoreError::Malformed(why) => write!(f, "malformed: {why}"),
            StoreError::Dimension { found, serving } => write!(
                f,
                "a {found}-D map where a {serving}-D one is expected (a daemon's `dimension` setting): \
                 give each dimension its own state directory"
            ),
            StoreError::Locked(dir) => write!(f, "another slamd uses the state directory {}", dir.display()),
            StoreError::Damaged {
                path,
                offset,
                reason,
                following,
            } => write!(
                f,
                "{}: the record at byte {offset} is damaged ({reason}) and {following} whole records follow it; \
                 a torn write damages only the last record, so this is corruption and nothing was changed. \
                 `slamd recover --state {}` keeps every record that can be verified",
                path.display(),
                path.parent().unwrap_or(Path::new(".")).display()
            ),
            StoreError::Mismatch { journal, map } => write!(
                f,
                "the journal follows map generation {journal}, but the map is at generation {map}: \
                 the map file is missing or was replaced"
            ),
        }
    }
}

impl std::error::Error for StoreError {}

/// Writes `bytes` to `tmp`, fsyncs it, renames it to `path` and fsyncs
/// the directory: afterwards `path` holds either the old file or the new
/// one, whole.
pub(crate) fn write_atomically(tmp: &Path, path: &Path, bytes: &[u8]) -> Result<(), StoreError> {
    let mut f = File::create(tmp).map_err(|e| StoreError::io("create", tmp, e))?;
    f.write_all(bytes)
        .and_then(|_| f.sync_all())
        .map_err(|e| StoreError::io("write", tmp, e))?;
    std::fs::rename(tmp, path).map_err(|e| StoreError::io("rename into", path, e))?;
    if let Some(dir) = path.parent() {
        let d = File::open(dir).map_err(|e| StoreError::io("open", dir, e))?;
        d.sync_all().map_err(|e| StoreError::io("fsync", dir, e))?;
    }
    Ok(())
}

/// What a state directory held when it was opened.
#[derive(Debug)]
pub struct Recovered<P: RigidMotion = Pose2> {
    /// The last checkpoint.
    pub map: Option<MapFile<P>>,
    /// The journal's records after it.
    pub tail: Vec<Record<P>>,
    /// Where the journal was cut, if it was.
    pub cut: Option<Cut>,
}

/// How the daemon keeps its state directory.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StateConfig {
    /// The directory (none: the map lives in memory only).
    pub dir: Option<PathBuf>,
    /// When the journal is fsynced.
    pub sync: SyncPolicy,
    /// The interval of [`SyncPolicy::Interval`].
    pub sync_interval_ms: u64,
    /// A checkpoint at least this often while input arrives.
    pub checkpoint_interval_s: f64,
    /// A checkpoint once the journal is this large.
    pub checkpoint_journal_mib: u64,
}

impl Default for StateConfig {
    fn default() -> Self {
        Self {
            dir: None,
            sync: SyncPolicy::Always,
            sync_interval_ms: 100,
            checkpoint_interval_s: 60.0,
            checkpoint_journal_mib: 64,
        }
    }
}

/// An open state directory: the lock, the journal being appended to.
pub struct StateDir {
    dir: PathBuf,
    journal: Journal,
    config: StateConfig,
    /// The map failed its checksum and the directory was taken up from the
    /// checkpoint before it: the next checkpoint replaces it.
    damaged_map: bool,
    _lock: File,
}

impl StateDir {
    /// Opens (creating) the directory, takes its lock, reads the map and
    /// the journal, cuts a torn journal tail and opens the journal for
    /// appending. A directory that cannot be written is an error here.
    ///
    /// `P` is the daemon's pose type: a directory that holds a map of the
    /// other dimension is refused ([`StoreError::Dimension`]).
    pub fn open<P: RigidMotion>(
        dir: &Path,
        config: &StateConfig,
    ) -> Result<(StateDir, Recovered<P>), StoreError> {
        std::fs::create_dir_all(dir).map_err(|e| StoreError::io("create", dir, e))?;
        let lock = lock(dir)?;
        let map_path = dir.join("map");
        let map = match std::fs::metadata(&map_path) {
            Ok(_) => Some(MapFile::read(&map_path)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(StoreError::io("read", &map_path, e)),
        };
        // a map that fails its checksum falls back to the checkpoint before
        // it and the two journals since, where they are whole
        let (map, before, damaged_map) = match map.transpose() {
            Ok(map) => (map, Vec::new(), false),
            // a damaged head can read as another version; a map truly of
            // another one has no readable `map.prev` either
            Err(
                e @ (StoreError::Corrupt { .. } | StoreError::NotOurs { .. } | StoreError::Version { .. }),
            ) => {
                let Some((previous, records)) = recovery::previous_checkpoint::<P>(dir) else {
                    return Err(e);
                };
                tracing::warn!(
                    error = %e,
                    generation = previous.generation,
                    "The map is damaged; continuing from the checkpoint before it and the journals since."
                );
                (Some(previous), records, true)
            }
            Err(e) => return Err(e),
        };
        // the journal that follows the map (after a fall-back: the damaged one)
        let generation = map
            .as_ref()
            .map_or(0, |m| m.generation.saturating_add(u64::from(damaged_map)));
        let interval = Duration::from_millis(config.sync_interval_ms);
        let mut recovered = Recovered {
            map,
            tail: before,
            cut: None,
        };
        // after a crash inside a checkpoint the journal that follows the
        // map may still be called journal.next
        let path = dir.join("journal");
        let next = dir.join("journal.next");
        let mut found = recovery::read(&path)?;
        if found.as_ref().is_none_or(|c| c.generation < generation) {
            if let Ok(Some(c)) = recovery::read(&next) {
                if c.generation == generation {
                    std::fs::rename(&next, &path).map_err(|e| StoreError::io("rename into", &path, e))?;
                    found = Some(c);
                }
            }
        }
        let _ = std::fs::remove_file(&next);
        let journal = match found {
            Some(c) if c.generation == generation => {
                let journal = if c.version < FORMAT_VERSION {
                    Journal::rewrite(&path, generation, &c.records, config.sync, interval)?
                } else {
                    Journal::append_to(&path, c.valid_len, generation, config.sync, interval)?
                };
                recovered.tail.extend(c.records);
                recovered.cut = c.cut;
                journal
            }
            Some(c) if c.generation > generation => {
                return Err(StoreError::Mismatch {
                    journal: c.generation,
                    map: generation,
                })
            }
            // missing, or already folded into the map
            _ => Journal::create(&path, generation, config.sync, interval)?,
        };
        let state = StateDir {
            dir: dir.to_path_buf(),
            journal,
            config: config.clone(),
            damaged_map,
            _lock: lock,
        };
        Ok((state, recovered))
    }

    /// The journal.
    pub fn journal(&mut self) -> &mut Journal {
        &mut self.journal
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Writes `map` as the next checkpoint and starts an empty journal
    /// after it: the new journal is made first (as `journal.next`), then
    /// the map is renamed into place, then the journal. A crash before the
    /// map's rename leaves the old map and journal; after it, an old
    /// journal that the next start drops (its records are in the map) and
    /// `journal.next`, which it takes. On an error before the map's
    /// rename nothing changed.
    ///
    /// The checkpoint it replaces and the journal after that are kept as
    /// `map.prev` and `journal.prev` (links, or copies where the file
    /// system has none): a map that later fails its checksum falls back to
    /// them. After such a fall-back the damaged map is kept as
    /// `map.damaged-SECONDS` instead, and `.prev` stays as it was.
    pub fn checkpoint<P: RigidMotion>(&mut self, mut map: MapFile<P>) -> Result<(), StoreError> {
        let generation = self.journal.generation() + 1;
        map.generation = generation;
        let interval = Duration::from_millis(self.config.sync_interval_ms);
        // what the map holds is in the journal being kept, as far as it can be
        let _ = self.journal.commit();
        if self.damaged_map {
            let aside = recovery::aside_name(&self.dir, "map.damaged")?;
            keep(&self.dir.join("map"), &aside)?;
        } else {
            // the journal first: a crash between the two leaves a pair of
            // generations that do not match, which no fall-back takes
            for name in ["journal", "map"] {
                let from = self.dir.join(name);
                if from.exists() {
                    let tmp = self.dir.join(format!("{name}.prev.tmp"));
                    keep(&from, &tmp)?;
                    let to = self.dir.join(format!("{name}.prev"));
                    std::fs::rename(&tmp, &to).map_err(|e| StoreError::io("rename into", &to, e))?;
                }
            }
        }
        let next = self.dir.join("journal.next");
        let journal = Journal::create(&next, generation, self.config.sync, interval)?;
        let path = self.dir.join("map");
        if let Err(e) = write_atomically(&self.dir.join("map.tmp"), &path, &map.encode()) {
            let _ = std::fs::remove_file(&next);
            return Err(e);
        }
        self.journal = journal;
        self.damaged_map = false;
        let path = self.dir.join("journal");
        std::fs::rename(&next, &path).map_err(|e| StoreError::io("rename into", &path, e))?;
        self.journal.moved_to(&path);
        Ok(())
    }

    /// Bytes in the journal file.
    pub fn journal_len(&self) -> u64 {
        self.journal.len()
    }

    /// Whether the journal has grown past its checkpoint size.
    pub fn journal_full(&self) -> bool {
        self.journal.len() >= self.config.checkpoint_journal_mib << 20
    }
}

/// A second name for the file at `from` (a hard link, or a copy where the
/// file system has none), replacing whatever `to` was.
fn keep(from: &Path, to: &Path) -> Result<(), StoreError> {
    let _ = std::fs::remove_file(to);
    std::fs::hard_link(from, to)
        .or_else(|_| std::fs::copy(from, to).map(|_| ()))
        .map_err(|e| StoreError::io("keep a copy of", from, e))
}

/// How long taking a state directory's lock waits for another holder.
const LOCK_PATIENCE: Duration = Duration::from_millis(500);

/// Takes the directory's lock file, or fails if another process holds it.
pub(super) fn lock(dir: &Path) -> Result<File, StoreError> {
    use std::os::fd::AsRawFd;
    let path = dir.join("lock");
    let f = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| StoreError::io("create", &path, e))?;
    // A process that forks while holding the lock leaves a copy of the
    // descriptor in the child until it execs, so a lock just released can
    // still be held for a moment: try again for a while before refusing.
    let deadline = std::time::Instant::now() + LOCK_PATIENCE;
    loop {
        // SAFETY: flock on a descriptor this function owns; no memory is shared.
        let r = unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
        if r == 0 {
            return Ok(f);
        }
        if std::time::Instant::now() >= deadline {
            return Err(StoreError::Locked(dir.to_path_buf()));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[cfg(test)]
mod tests;
