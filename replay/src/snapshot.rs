//! Snapshots: every table's content in one versioned, checksummed file,
//! written atomically and restored at start.
//!
//! A snapshot is `snapshot-<seq>.crsnap` in the snapshot directory. It is
//! written to a temporary file, fsynced, renamed into place, the directory
//! fsynced, then read back and checked before older snapshots are pruned
//! (the newest `keep` stay). A crash at any point leaves the previous
//! snapshots as they were. Each snapshot first seals the write-ahead log's
//! segment ([`crate::wal`]). The format: [`with_header`] and [`encode`].
//!
//! At start the newest valid snapshot is restored
//! ([`Snapshots::restore_latest`]). A truncated file fails the length
//! check, a flipped bit a checksum; either is reported with the file's path
//! and the file is renamed `*.corrupt`, never deleted or overwritten. A
//! snapshot holding a table the server does not serve is an error
//! (`server`), and a restored image must hold only what valid batches could
//! have put there, or `Table::restore` refuses it: samples are not checked
//! again.

use std::fs::{self, File};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crossroads_types::ObservationLayout;
use crossroads_types::columns::{Columns, ROW_BYTES};

use crate::metrics::ReplayMetrics;
use crate::table::{Table, TableImage};
use crate::wal::{Wal, WalError};

/// First bytes of every snapshot.
pub const MAGIC: &[u8; 8] = b"CRRPLSNP";
/// Version of the format written. Version 2 stores the layout (kind,
/// channels, rows, cols, extra; spec flag 2). Version 1, written by earlier
/// builds, stored the kind and a flat shape (spec flag 1); it is still read,
/// as a legacy layout of that kind and length (`ObservationLayout::legacy`),
/// which the table replaces with the layout of its next insert of the same
/// kind and length.
pub const FORMAT_VERSION: u32 = 2;
/// Spec flag of a table with no layout yet.
const NO_SPEC: u8 = 0;
/// Spec flag of a kind and a flat shape, as version 1 stored it.
const LEGACY_SPEC: u8 = 1;
/// Spec flag of a kind and a layout.
const LAYOUT_SPEC: u8 = 2;
const HEADER_LEN: usize = 32;
const PREFIX: &str = "snapshot-";
const SUFFIX: &str = ".crsnap";

/// Why a snapshot could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// A file operation failed.
    #[error("snapshot {}: {what}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a valid snapshot.
    #[error("snapshot {} is corrupt: {problem}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong: truncated, checksum mismatch, unknown version...
        problem: String,
    },
    /// The write-ahead log could not be sealed before the copy.
    #[error(transparent)]
    Wal(#[from] WalError),
    /// Snapshots exist but none is valid; starting empty would silently
    /// lose them.
    #[error(
        "no valid snapshot in {}: {}; move the files away or set replay.restore = false to start empty",
        dir.display(),
        problems.join("; ")
    )]
    NoValidSnapshot {
        /// The directory.
        dir: PathBuf,
        /// Each corrupt file and its problem.
        problems: Vec<String>,
    },
}

fn io(path: &Path, what: &'static str) -> impl FnOnce(std::io::Error) -> SnapshotError {
    let path = path.to_path_buf();
    move |source| SnapshotError::Io { path, what, source }
}

/// What a written snapshot holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    /// Its path.
    pub path: PathBuf,
    /// Items across tables.
    pub items: u64,
    /// File size.
    pub bytes: u64,
    /// Time from the first copy to the rename.
    pub duration: Duration,
}

/// Encodes table images into a snapshot file's bytes, little-endian: the
/// header ([`with_header`]), then the body: the table count, and per table
/// its name, observation layout and action count, keys, counters, item
/// columns (oldest first) and compact observations.
pub fn encode(tables: &[(String, TableImage)]) -> Vec<u8> {
    let mut body = Vec::new();
    put_u32(&mut body, tables.len() as u32);
    for (name, t) in tables {
        encode_table(&mut body, name, t);
    }
    with_header(&body)
}

/// A snapshot file's bytes of `body`: the 32-byte header ([`MAGIC`], format
/// version u32, flags u32, body length u64, CRC-32 of the body u32, CRC-32
/// of the header's first 28 bytes u32) and the body. [`encode`] writes its body through it;
/// the fuzz target uses it to reach the body's decoder past the
/// checksums.
pub fn with_header(body: &[u8]) -> Vec<u8> {
    let mut file = Vec::with_capacity(HEADER_LEN + body.len());
    file.extend_from_slice(MAGIC);
    put_u32(&mut file, FORMAT_VERSION);
    put_u32(&mut file, 0);
    put_u64(&mut file, body.len() as u64);
    put_u32(&mut file, crc32fast::hash(body));
    let header_crc = crc32fast::hash(&file);
    put_u32(&mut file, header_crc);
    file.extend_from_slice(body);
    file
}

/// Appends one table's name and image (the body of a snapshot holds one
/// per table; a write-ahead-log record holds one batch as a small image).
pub(crate) fn encode_table(body: &mut Vec<u8>, name: &str, t: &TableImage) {
    put_str(body, name);
    match &t.spec {
        Some((layout, actions)) => {
            body.push(LAYOUT_SPEC);
            put_str(body, &layout.kind);
            // A table's layout is valid: each value fits a u32.
            for d in [layout.channels, layout.rows, layout.cols, layout.extra] {
                put_u32(body, u32::try_from(d).unwrap_or(u32::MAX));
            }
            put_u32(body, *actions);
        }
        None => body.push(NO_SPEC),
    }
    // Format 1 stores the insert and sample counts twice (once more as
    // the rate limiter's, which are the same counts).
    for v in [
        t.next_key,
        t.inserts_total,
        t.samples_total,
        t.priority_updates_total,
        t.ignored_updates_total,
        t.inserts_total,
        t.samples_total,
        t.len() as u64,
    ] {
        put_u64(body, v);
    }
    let start = body.len();
    body.resize(start + t.items.byte_len(), 0);
    t.items.write_le(&mut body[start..]);
    put_u64(body, t.observation_offsets.len() as u64);
    t.observation_offsets.iter().for_each(|v| put_u64(body, *v));
    put_u64(body, t.observation_data.len() as u64);
    body.extend_from_slice(&t.observation_data);
}

/// Decodes a snapshot file's bytes; every length is checked, so a damaged
/// file is an error (naming the problem), never a panic or a huge
/// allocation.
pub fn decode(bytes: &[u8]) -> Result<Vec<(String, TableImage)>, String> {
    if bytes.len() < HEADER_LEN {
        return Err(format!(
            "truncated: {} bytes, shorter than the header",
            bytes.len()
        ));
    }
    let (header, body) = bytes.split_at(HEADER_LEN);
    if &header[..8] != MAGIC {
        return Err("not a crossroads replay snapshot (bad magic)".to_owned());
    }
    let mut h = Reader::new(&header[8..]);
    let version = h.u32()?;
    let _flags = h.u32()?;
    let body_len = h.u64()?;
    let body_crc = h.u32()?;
    let header_crc = h.u32()?;
    if crc32fast::hash(&header[..28]) != header_crc {
        return Err("header checksum mismatch".to_owned());
    }
    if !(1..=FORMAT_VERSION).contains(&version) {
        return Err(format!(
            "format version {version}, this build reads 1 to {FORMAT_VERSION}"
        ));
    }
    if body.len() as u64 != body_len {
        return Err(format!(
            "truncated or extended: body is {} bytes, the header says {body_len}",
            body.len()
        ));
    }
    if crc32fast::hash(body) != body_crc {
        return Err("body checksum mismatch".to_owned());
    }
    let mut r = Reader::new(body);
    let n_tables = r.u32()?;
    let mut tables = Vec::new();
    for _ in 0..n_tables {
        tables.push(decode_table(&mut r)?);
    }
    if r.remaining() != 0 {
        return Err(format!("{} bytes after the last table", r.remaining()));
    }
    Ok(tables)
}

/// Reads one table's name and image, as [`encode_table`] wrote it;
/// every length and offset is checked.
pub(crate) fn decode_table(r: &mut Reader<'_>) -> Result<(String, TableImage), String> {
    let name = r.str()?;
    let spec = match r.u8()? {
        NO_SPEC => None,
        LEGACY_SPEC => {
            let kind = r.str()?;
            let rank = r.u32()? as usize;
            let shape = r.u32s(rank)?;
            let actions = r.u32()?;
            // An empty shape had no length: 0, refused at restore.
            let len = if shape.is_empty() {
                Some(0)
            } else {
                shape.iter().try_fold(1u32, |len, d| len.checked_mul(*d))
            };
            let len = len.ok_or_else(|| {
                format!("table {name}: shape {shape:?} has more values than any observation")
            })?;
            Some((ObservationLayout::legacy(kind, i64::from(len)), actions))
        }
        LAYOUT_SPEC => {
            let kind = r.str()?;
            let (channels, rows, cols, extra) = (r.u32()?, r.u32()?, r.u32()?, r.u32()?);
            let layout = ObservationLayout::new(
                kind,
                i64::from(channels),
                i64::from(rows),
                i64::from(cols),
                i64::from(extra),
            );
            Some((layout, r.u32()?))
        }
        other => return Err(format!("table {name}: bad spec flag {other}")),
    };
    let mut image = TableImage {
        spec,
        next_key: r.u64()?,
        inserts_total: r.u64()?,
        samples_total: r.u64()?,
        priority_updates_total: r.u64()?,
        ignored_updates_total: r.u64()?,
        ..TableImage::default()
    };
    // The same counts again, as the rate limiter's (see `encode_table`).
    let _limiter_counts = (r.u64()?, r.u64()?);
    let n = r.len(ROW_BYTES)?;
    image.items = Columns::read_le(r.bytes(n * ROW_BYTES)?).ok_or("rows of 24 bytes")?;
    let n_obs = r.len(8)?;
    image.observation_offsets = (0..n_obs).map(|_| r.u64()).collect::<Result<_, _>>()?;
    let data_len = r.len(1)?;
    image.observation_data = r.bytes(data_len)?.to_vec();
    let mut previous = 0;
    for (i, off) in image.observation_offsets.iter().enumerate() {
        if *off < previous || *off > data_len as u64 {
            return Err(format!("table {name}: observation offset {i} out of order"));
        }
        previous = *off;
    }
    Ok((name, image))
}

/// Reads and checks one snapshot file.
pub fn read(path: &Path) -> Result<Vec<(String, TableImage)>, SnapshotError> {
    let mut bytes = Vec::new();
    File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(io(path, "reading"))?;
    decode(&bytes).map_err(|problem| SnapshotError::Corrupt {
        path: path.to_path_buf(),
        problem,
    })
}

/// A restored snapshot: its path and its tables by name.
pub type Restored = (PathBuf, Vec<(String, TableImage)>);

/// Writes and restores the server's snapshots in one directory.
#[derive(Debug)]
pub struct Snapshots {
    dir: PathBuf,
    keep: usize,
    metrics: ReplayMetrics,
    /// The write-ahead log each snapshot seals and, once written, trims.
    wal: std::sync::OnceLock<Arc<Wal>>,
    /// One writer at a time (periodic, on request, at shutdown).
    writing: std::sync::Mutex<()>,
}

impl Snapshots {
    /// Snapshots in `dir` (created if missing), keeping the newest `keep`.
    pub fn new(dir: PathBuf, keep: usize, metrics: ReplayMetrics) -> Result<Self, SnapshotError> {
        fs::create_dir_all(&dir).map_err(io(&dir, "creating the directory"))?;
        // Temporary files of a write that crashed are never valid snapshots.
        for entry in fs::read_dir(&dir).map_err(io(&dir, "listing"))?.flatten() {
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name.starts_with(&format!(".{PREFIX}")) && name.ends_with(".tmp") {
                let _ = fs::remove_file(entry.path());
            }
        }
        Ok(Self {
            dir,
            keep: keep.max(1),
            metrics,
            wal: std::sync::OnceLock::new(),
            writing: std::sync::Mutex::new(()),
        })
    }

    /// From now on, seals `wal` before each copy and deletes the sealed
    /// segments once the snapshot is written and reads back. Once only: a
    /// second log is ignored.
    pub fn attach_wal(&self, wal: Arc<Wal>) {
        let _ = self.wal.set(wal);
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Snapshot files by sequence number, newest first.
    fn list(&self) -> Result<Vec<(u64, PathBuf)>, SnapshotError> {
        let mut found =
            numbered_files(&self.dir, PREFIX, SUFFIX).map_err(io(&self.dir, "listing"))?;
        found.reverse();
        Ok(found)
    }

    fn next_seq(&self) -> Result<u64, SnapshotError> {
        let mut max = self.list()?.first().map_or(0, |(s, _)| *s);
        // Corrupt files renamed aside keep their number out of reuse.
        for entry in fs::read_dir(&self.dir)
            .map_err(io(&self.dir, "listing"))?
            .flatten()
        {
            if let Some(seq) = entry
                .file_name()
                .to_str()
                .and_then(|n| n.strip_prefix(PREFIX))
                .and_then(|n| n.split('.').next())
                .and_then(|n| n.parse::<u64>().ok())
            {
                max = max.max(seq);
            }
        }
        Ok(max + 1)
    }

    /// Writes every table to a new snapshot, atomically; prunes older ones
    /// once the new one reads back valid. Blocking: call it off the async
    /// runtime (`spawn_blocking`).
    pub fn write(&self, tables: &[Arc<Table>]) -> Result<Written, SnapshotError> {
        let _one_at_a_time = self.writing.lock().unwrap_or_else(|p| p.into_inner());
        let start = Instant::now();
        let result = self.write_inner(tables, start);
        match &result {
            Ok(w) => {
                self.metrics.snapshots.with_label_values(&["ok"]).inc();
                self.metrics.snapshot_duration.set(w.duration.as_secs_f64());
                self.metrics.snapshot_bytes.set(w.bytes as i64);
                self.metrics.snapshot_done();
                tracing::info!(path = %w.path.display(), items = w.items, bytes = w.bytes,
                    seconds = w.duration.as_secs_f64(), "snapshot written");
            }
            Err(e) => {
                self.metrics.snapshots.with_label_values(&["error"]).inc();
                tracing::error!(error = %e, "snapshot failed");
            }
        }
        result
    }

    fn write_inner(&self, tables: &[Arc<Table>], start: Instant) -> Result<Written, SnapshotError> {
        // Every record in a sealed segment was inserted before the copy
        // below, so the snapshot holds it.
        let sealed = self.wal.get().map(|w| w.rotate()).transpose()?;
        let images: Vec<(String, TableImage)> = tables
            .iter()
            .map(|t| (t.name().to_owned(), t.image()))
            .collect();
        let items = images.iter().map(|(_, i)| i.len() as u64).sum();
        let bytes = encode(&images);
        drop(images);
        let seq = self.next_seq()?;
        let path = self.dir.join(format!("{PREFIX}{seq:010}{SUFFIX}"));
        let tmp = self.dir.join(format!(".{PREFIX}{seq:010}.tmp"));
        let written = (|| {
            let mut f = File::create(&tmp)?;
            f.write_all(&bytes)?;
            f.sync_all()
        })();
        if let Err(e) = written {
            let _ = fs::remove_file(&tmp);
            return Err(io(&tmp, "writing")(e));
        }
        fs::rename(&tmp, &path).map_err(io(&path, "renaming into place"))?;
        File::open(&self.dir)
            .and_then(|d| d.sync_all())
            .map_err(io(&self.dir, "syncing the directory"))?;
        let duration = start.elapsed();
        // Only a snapshot that reads back valid may replace older ones.
        read(&path)?;
        for (_, old) in self.list()?.into_iter().skip(self.keep) {
            if let Err(e) = fs::remove_file(&old) {
                tracing::warn!(path = %old.display(), error = %e, "cannot prune old snapshot");
            }
        }
        if let (Some(wal), Some(seq)) = (self.wal.get(), sealed) {
            // Segments left behind are read again at start, their records
            // found in this snapshot by key: harmless.
            if let Err(e) = wal.delete_through(seq) {
                tracing::warn!(error = %e, "cannot delete write-ahead-log segments the snapshot holds");
            }
        }
        Ok(Written {
            path,
            items,
            bytes: bytes.len() as u64,
            duration,
        })
    }

    /// The newest valid snapshot's tables, if any. Corrupt snapshots are
    /// reported, renamed `*.corrupt` (kept for inspection) and skipped for
    /// an older valid one; if snapshots exist and none is valid, that is an
    /// error rather than a silent empty start (which would prune them).
    pub fn restore_latest(&self) -> Result<Option<Restored>, SnapshotError> {
        let mut problems = Vec::new();
        for (_, path) in self.list()? {
            match read(&path) {
                Ok(tables) => {
                    for p in &problems {
                        tracing::error!(problem = %p, "skipped a corrupt snapshot");
                    }
                    self.metrics.snapshot_done();
                    return Ok(Some((path, tables)));
                }
                Err(SnapshotError::Corrupt { path, problem }) => {
                    tracing::error!(path = %path.display(), %problem, "snapshot is corrupt; renaming it *.corrupt");
                    let aside = path.with_extension("crsnap.corrupt");
                    if let Err(e) = fs::rename(&path, &aside) {
                        tracing::warn!(path = %path.display(), error = %e, "cannot rename corrupt snapshot");
                    }
                    problems.push(format!(
                        "{} ({problem}; now {})",
                        path.display(),
                        aside.display()
                    ));
                }
                Err(e) => return Err(e),
            }
        }
        if problems.is_empty() {
            Ok(None)
        } else {
            Err(SnapshotError::NoValidSnapshot {
                dir: self.dir.clone(),
                problems,
            })
        }
    }
}

/// The files `<prefix><number><suffix>` of `dir` by number, smallest
/// first (snapshots and write-ahead-log segments).
pub(crate) fn numbered_files(
    dir: &Path,
    prefix: &str,
    suffix: &str,
) -> std::io::Result<Vec<(u64, PathBuf)>> {
    let mut found = Vec::new();
    for entry in fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        if let Some(seq) = name
            .strip_prefix(prefix)
            .and_then(|s| s.strip_suffix(suffix))
            .and_then(|s| s.parse::<u64>().ok())
        {
            found.push((seq, entry.path()));
        }
    }
    found.sort_by_key(|(seq, _)| *seq);
    Ok(found)
}

pub(crate) fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

pub(crate) fn put_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_str(out: &mut Vec<u8>, s: &str) {
    put_u32(out, s.len() as u32);
    out.extend_from_slice(s.as_bytes());
}

/// A bounds-checked cursor.
pub(crate) struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, at: 0 }
    }

    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() - self.at
    }

    pub(crate) fn bytes(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self
            .at
            .checked_add(n)
            .filter(|e| *e <= self.bytes.len())
            .ok_or_else(|| {
                format!(
                    "truncated: {n} bytes wanted at offset {}, {} left",
                    self.at,
                    self.remaining()
                )
            })?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.bytes(1)?[0])
    }

    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        let b = self.bytes(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub(crate) fn u64(&mut self) -> Result<u64, String> {
        let b = self.bytes(8)?;
        let mut a = [0; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    /// A count whose items take at least `unit` bytes each: bounded by
    /// what is left, so a damaged count cannot ask for a huge allocation.
    fn len(&mut self, unit: usize) -> Result<usize, String> {
        let n = self.u64()?;
        if n.saturating_mul(unit as u64) > self.remaining() as u64 {
            return Err(format!("truncated: a count of {n} exceeds the bytes left"));
        }
        Ok(n as usize)
    }

    fn u32s(&mut self, n: usize) -> Result<Vec<u32>, String> {
        let b = self.bytes(n.checked_mul(4).ok_or("count overflow")?)?;
        Ok(b.chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }

    fn str(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        let b = self.bytes(n)?;
        String::from_utf8(b.to_vec()).map_err(|_| "a name is not UTF-8".to_owned())
    }
}
