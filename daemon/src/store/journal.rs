//! The write-ahead journal: every message the daemon takes in, framed and
//! checksummed, appended in the order the engine applied them.
//!
//! File: a 24-byte head `"SLAMDJNL" | version: u32 | crc32c: u32 |
//! generation: u64` (the map generation it follows; the checksum covers
//! the other three fields), then one frame per [`Record`].
//! Records are buffered and written by [`Journal::commit`], once per batch
//! (group commit), before the snapshot that acknowledges them goes out.

use super::bytes::{frame, Put};
use super::record::Record;
use super::{StoreError, SyncPolicy, FORMAT_VERSION, OLDEST_FORMAT};
use slamd_types::RigidMotion;
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The journal file's first bytes.
pub const MAGIC: &[u8; 8] = b"SLAMDJNL";
/// Bytes before the first record.
pub const HEAD: usize = 24;

/// An open journal, appending.
pub struct Journal {
    file: File,
    path: PathBuf,
    /// Encoded records not yet written.
    pending: Vec<u8>,
    /// Bytes on disk that hold whole records (the head included).
    written: u64,
    policy: SyncPolicy,
    interval: Duration,
    last_sync: Instant,
    /// Written since the last fsync.
    unsynced: bool,
    generation: u64,
}

/// A file's head: `magic | version | crc32c | generation`.
pub(super) fn head(magic: &[u8; 8], generation: u64) -> Vec<u8> {
    let mut p = Put::default();
    p.0.extend_from_slice(magic);
    p.u32(FORMAT_VERSION);
    p.u32(head_crc(magic, FORMAT_VERSION, generation));
    p.u64(generation);
    p.0
}

pub(super) fn head_crc(magic: &[u8; 8], version: u32, generation: u64) -> u32 {
    let crc = crc32c::crc32c(magic);
    let crc = crc32c::crc32c_append(crc, &version.to_le_bytes());
    crc32c::crc32c_append(crc, &generation.to_le_bytes())
}

/// Checks a file's head: magic, format version, checksum. Returns the
/// generation and the version.
pub(super) fn check_head(
    path: &Path,
    bytes: &[u8],
    magic: &[u8; 8],
    what: &str,
) -> Result<(u64, u32), StoreError> {
    if bytes.len() < 8 || &bytes[..8] != magic {
        return Err(StoreError::NotOurs {
            path: path.to_path_buf(),
            what: what.into(),
        });
    }
    let field = |at: usize, n: usize| bytes.get(at..at + n).unwrap_or_default();
    let version = u32::from_le_bytes(field(8, 4).try_into().unwrap_or_default());
    if bytes.len() >= 12 && !(OLDEST_FORMAT..=FORMAT_VERSION).contains(&version) {
        return Err(StoreError::Version {
            path: path.to_path_buf(),
            found: version,
        });
    }
    let crc = u32::from_le_bytes(field(12, 4).try_into().unwrap_or_default());
    let generation = u64::from_le_bytes(field(16, 8).try_into().unwrap_or_default());
    if bytes.len() < HEAD || crc != head_crc(magic, version, generation) {
        return Err(StoreError::Corrupt {
            path: path.to_path_buf(),
            why: format!("its {what} head is damaged"),
        });
    }
    Ok((generation, version))
}

impl Journal {
    /// A new, empty journal following map `generation`, replacing any
    /// file at `path` atomically (written beside it, fsynced, renamed).
    pub fn create(
        path: &Path,
        generation: u64,
        policy: SyncPolicy,
        interval: Duration,
    ) -> Result<Self, StoreError> {
        let tmp = path.with_extension("tmp");
        super::write_atomically(&tmp, path, &head(MAGIC, generation))?;
        Self::append_to(path, HEAD as u64, generation, policy, interval)
    }

    /// A journal following map `generation` that holds `records`, in this
    /// version's format, replacing the file at `path` atomically: how a
    /// journal of an older format is taken up, so that no record of this
    /// format ever sits under an older head (which an older slamd would
    /// cut as a corrupt tail).
    pub fn rewrite<P: RigidMotion>(
        path: &Path,
        generation: u64,
        records: &[Record<P>],
        policy: SyncPolicy,
        interval: Duration,
    ) -> Result<Self, StoreError> {
        let mut bytes = head(MAGIC, generation);
        for r in records {
            let mut p = Put::default();
            r.encode(&mut p);
            frame(&mut bytes, &p.0);
        }
        let tmp = path.with_extension("tmp");
        super::write_atomically(&tmp, path, &bytes)?;
        Self::append_to(path, bytes.len() as u64, generation, policy, interval)
    }

    /// Opens an existing journal to append after its first `valid_len`
    /// bytes; whatever follows them (a torn record) is cut off.
    pub fn append_to(
        path: &Path,
        valid_len: u64,
        generation: u64,
        policy: SyncPolicy,
        interval: Duration,
    ) -> Result<Self, StoreError> {
        let mut file = OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| StoreError::io("open", path, e))?;
        file.set_len(valid_len)
            .and_then(|_| file.sync_all())
            .and_then(|_| file.seek(SeekFrom::Start(valid_len)).map(|_| ()))
            .map_err(|e| StoreError::io("cut", path, e))?;
        Ok(Self {
            file,
            path: path.to_path_buf(),
            pending: Vec::new(),
            written: valid_len,
            policy,
            interval,
            last_sync: Instant::now(),
            unsynced: false,
            generation,
        })
    }

    /// Buffers one record for the next [`Self::commit`].
    pub fn append<P: RigidMotion>(&mut self, r: &Record<P>) {
        let mut p = Put::default();
        r.encode(&mut p);
        frame(&mut self.pending, &p.0);
    }

    /// Writes the buffered records and syncs as the policy says (always:
    /// fsync now; interval: once the interval has passed; never: the OS
    /// decides). On failure the file is cut back to its last whole record
    /// and the records stay buffered for the next commit: nothing is lost
    /// and no torn record is left between two whole ones.
    pub fn commit(&mut self) -> Result<(), StoreError> {
        if !self.pending.is_empty() {
            if let Err(e) = self.file.write_all(&self.pending) {
                let _ = self.file.set_len(self.written);
                let _ = self.file.seek(SeekFrom::Start(self.written));
                return Err(StoreError::io("append to", &self.path, e));
            }
            self.written += self.pending.len() as u64;
            self.pending.clear();
            self.unsynced = true;
        }
        let due = match self.policy {
            SyncPolicy::Always => true,
            SyncPolicy::Interval => self.last_sync.elapsed() >= self.interval,
            SyncPolicy::Never => false,
        };
        if due {
            self.sync()?;
        }
        Ok(())
    }

    /// With [`SyncPolicy::Interval`], fsyncs what was written once the
    /// interval has passed, even when no new batch comes to do it (the
    /// daemon calls this on every tick).
    pub fn sync_if_due(&mut self) -> Result<(), StoreError> {
        if self.policy == SyncPolicy::Interval && self.unsynced && self.last_sync.elapsed() >= self.interval {
            self.sync()?;
        }
        Ok(())
    }

    /// fsyncs what was written, whatever the policy.
    pub fn sync(&mut self) -> Result<(), StoreError> {
        if self.unsynced {
            self.file
                .sync_data()
                .map_err(|e| StoreError::io("fsync", &self.path, e))?;
            self.unsynced = false;
        }
        self.last_sync = Instant::now();
        Ok(())
    }

    /// The file was renamed to `path` (errors name it from now on).
    pub fn moved_to(&mut self, path: &Path) {
        self.path = path.to_path_buf();
    }

    /// Bytes written (the head included).
    pub fn len(&self) -> u64 {
        self.written
    }

    /// Whether it holds no record.
    pub fn is_empty(&self) -> bool {
        self.written <= HEAD as u64 && self.pending.is_empty()
    }

    /// The map generation it follows.
    pub fn generation(&self) -> u64 {
        self.generation
    }
}
