//! The write-ahead log: an acknowledged insert survives a kill -9.
//!
//! With the log on, an insert is acknowledged only once its batch is in
//! the log and fsynced, and it enters the table only then: a batch whose
//! record fails is neither sampled nor kept, so the actor's resend stores
//! it once. The insert reserves its room in the table first (the rate
//! limiter's wait and the spec check, [`Table::reserve`]) and hands the
//! reservation to the log ([`Wal::append`]). One writer thread appends and
//! fsyncs records in groups (group commit) and gives each record its
//! table's keys, so the keys in the log are the keys in the table.
//!
//! The log is a folder of segments `wal-<seq>.log` beside the snapshots
//! ([`segment_header`], [`encode_record`]). A snapshot seals the current
//! segment before it copies the tables ([`Wal::rotate`]) and deletes the
//! sealed segments once it reads back ([`Wal::delete_through`]). At start
//! the newest snapshot is restored, the records it lacks are inserted again
//! ([`replay_into`]), and a snapshot is written at once so the log starts
//! again from empty. A failed write: [`Wal::check_writable`].

use std::collections::BTreeMap;
use std::fs::{self, File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use parking_lot::Mutex;

use crate::metrics::ReplayMetrics;
use crate::snapshot::{self, Reader};
use crate::table::{Inserted, PreparedBatch, Reservation, Table, TableImage};

/// First bytes of every segment.
pub const MAGIC: &[u8; 8] = b"CRRPLWAL";
/// Version of the format written. Version 2 records hold the observation
/// layout; version 1 segments, of earlier builds, are still read (their
/// flat shape as a legacy layout, as in [`snapshot`]).
pub const FORMAT_VERSION: u32 = 2;
const HEADER_LEN: usize = 16;
const PREFIX: &str = "wal-";
const SUFFIX: &str = ".log";
/// How long inserts are refused after a failed write before one tries
/// again.
const RETRY_AFTER: Duration = Duration::from_secs(1);

/// Why the log could not take or keep a record.
#[derive(Debug, Clone, thiserror::Error)]
pub enum WalError {
    /// A file operation failed.
    #[error("write-ahead log {}: {what}: {message}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The I/O error.
        message: String,
    },
    /// A write failed recently; inserts are refused until it writes again.
    #[error(
        "write-ahead log failed {:.1} s ago ({cause}); inserts are refused (nothing stored) \
         and retried after {} s",
        ago.as_secs_f64(),
        RETRY_AFTER.as_secs()
    )]
    Unavailable {
        /// Since the failure.
        ago: Duration,
        /// The failure.
        cause: String,
    },
    /// A segment does not hold together where it must (its header).
    #[error("write-ahead log {} is corrupt: {problem}", path.display())]
    Corrupt {
        /// The segment.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A record names a table this server does not serve.
    #[error(
        "write-ahead log {} holds batches of table {table:?}, which this server does not serve; \
         set replay.table to it, or replay.restore = false to start empty (the log is then set aside)",
        path.display()
    )]
    UnknownTable {
        /// The segment.
        path: PathBuf,
        /// The table.
        table: String,
    },
    /// The writer thread has stopped.
    #[error("the write-ahead log's writer has stopped")]
    Stopped,
}

fn io(path: &Path, what: &'static str) -> impl FnOnce(std::io::Error) -> WalError {
    let path = path.to_path_buf();
    move |e| WalError::Io {
        path,
        what,
        message: e.to_string(),
    }
}

/// How the log writes.
#[derive(Debug, Clone)]
pub struct WalConfig {
    /// Its folder.
    pub dir: PathBuf,
    /// Longest a record waits for others to share its fsync.
    pub sync_interval: Duration,
    /// A group this large is written at once.
    pub sync_bytes: usize,
}

/// Appends one framed record of `image` in table `table` to `out`
/// (little-endian): the body's length u32, its CRC-32 u32, then the body,
/// the table's name and image as a snapshot stores it
/// (`snapshot::encode_table`). The image's keys say where the batch sits.
/// A crash during a write leaves at most a torn last record, which fails
/// its length or checksum: reading stops there and keeps what came before.
pub fn encode_record(out: &mut Vec<u8>, table: &str, image: &TableImage) {
    let at = out.len();
    out.extend_from_slice(&[0; 8]);
    snapshot::encode_table(out, table, image);
    let body_len = (out.len() - at - 8) as u32;
    let crc = crc32fast::hash(&out[at + 8..]);
    out[at..at + 4].copy_from_slice(&body_len.to_le_bytes());
    out[at + 4..at + 8].copy_from_slice(&crc.to_le_bytes());
}

/// The segment header, 16 bytes: [`MAGIC`], [`FORMAT_VERSION`] as a
/// little-endian u32 and the CRC-32 of those 12 bytes.
pub fn segment_header() -> [u8; HEADER_LEN] {
    let mut h = [0; HEADER_LEN];
    h[..8].copy_from_slice(MAGIC);
    h[8..12].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    let crc = crc32fast::hash(&h[..12]);
    h[12..].copy_from_slice(&crc.to_le_bytes());
    h
}

/// What one segment's bytes hold.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Decoded {
    /// The whole records, in file order: table and image.
    pub records: Vec<(String, TableImage)>,
    /// Bytes up to the end of the last whole record.
    pub valid_len: usize,
    /// Why reading stopped before the end, if it did (a torn last record
    /// after a crash, or damage).
    pub torn: Option<String>,
}

/// Reads a segment's bytes: the header must be whole and right (else an
/// error naming the problem); records are read until the end or the first
/// that is not whole (torn), never panicking or allocating more than the
/// bytes given.
pub fn decode_segment(bytes: &[u8]) -> Result<Decoded, String> {
    if bytes.len() < HEADER_LEN {
        return Err(format!(
            "truncated: {} bytes, shorter than the header",
            bytes.len()
        ));
    }
    let (header, mut rest) = bytes.split_at(HEADER_LEN);
    if &header[..8] != MAGIC {
        return Err("not a crossroads write-ahead log (bad magic)".to_owned());
    }
    if crc32fast::hash(&header[..12]).to_le_bytes() != header[12..16] {
        return Err("header checksum mismatch".to_owned());
    }
    let version = u32::from_le_bytes([header[8], header[9], header[10], header[11]]);
    if !(1..=FORMAT_VERSION).contains(&version) {
        return Err(format!(
            "format version {version}, this build reads 1 to {FORMAT_VERSION}"
        ));
    }
    let mut out = Decoded {
        valid_len: HEADER_LEN,
        ..Decoded::default()
    };
    while !rest.is_empty() {
        let at = out.valid_len;
        if rest.len() < 8 {
            out.torn = Some(format!("{} bytes at offset {at}, not a record", rest.len()));
            break;
        }
        let len = u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]) as usize;
        let crc = u32::from_le_bytes([rest[4], rest[5], rest[6], rest[7]]);
        let Some(body) = rest.get(8..8 + len) else {
            out.torn = Some(format!(
                "the record at offset {at} says {len} bytes, {} are left",
                rest.len() - 8
            ));
            break;
        };
        if crc32fast::hash(body) != crc {
            out.torn = Some(format!("the record at offset {at} fails its checksum"));
            break;
        }
        let mut r = Reader::new(body);
        match snapshot::decode_table(&mut r) {
            Ok(record) if r.remaining() == 0 => out.records.push(record),
            Ok(_) => {
                out.torn = Some(format!(
                    "the record at offset {at} has {} bytes after its batch",
                    r.remaining()
                ));
                break;
            }
            Err(problem) => {
                out.torn = Some(format!("the record at offset {at}: {problem}"));
                break;
            }
        }
        out.valid_len += 8 + len;
        rest = &rest[8 + len..];
    }
    Ok(out)
}

/// Segment files of `dir` by sequence number, oldest first.
fn segments(dir: &Path) -> Result<Vec<(u64, PathBuf)>, WalError> {
    snapshot::numbered_files(dir, PREFIX, SUFFIX).map_err(io(dir, "listing"))
}

fn sync_dir(dir: &Path) -> Result<(), WalError> {
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(io(dir, "syncing the folder"))
}

/// What [`replay_into`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Replayed {
    /// Segments read.
    pub segments: usize,
    /// Records the restored snapshot already held.
    pub covered: u64,
    /// Batches inserted again.
    pub batches: u64,
    /// Their transitions.
    pub transitions: u64,
    /// Segments that ended in a torn or damaged record.
    pub torn: usize,
}

/// Inserts again, into `tables` (restored from the newest snapshot), every
/// batch of the log in `dir` that they do not hold, oldest key first, so
/// each takes the key it was logged with.
/// A segment whose header is damaged is renamed `*.corrupt` (kept) and
/// skipped; a torn record ends its segment's reading (what came before
/// counts). Blocking.
pub fn replay_into(
    dir: &Path,
    tables: &BTreeMap<String, Arc<Table>>,
) -> Result<Replayed, WalError> {
    let mut done = Replayed::default();
    let mut by_table: BTreeMap<&str, Vec<(u64, PreparedBatch)>> = BTreeMap::new();
    if !dir.exists() {
        return Ok(done);
    }
    for (_, path) in segments(dir)? {
        let bytes = fs::read(&path).map_err(io(&path, "reading"))?;
        done.segments += 1;
        let decoded = match decode_segment(&bytes) {
            Ok(d) => d,
            Err(problem) => {
                let aside = path.with_extension("log.corrupt");
                tracing::error!(path = %path.display(), %problem, aside = %aside.display(),
                    "write-ahead log segment is corrupt; setting it aside");
                fs::rename(&path, &aside).map_err(io(&path, "setting aside"))?;
                continue;
            }
        };
        if let Some(problem) = &decoded.torn {
            done.torn += 1;
            tracing::warn!(path = %path.display(), %problem, kept = decoded.records.len(),
                "write-ahead log segment ends in a torn record (a write the crash cut short); \
                 keeping the records before it");
        }
        for (name, image) in decoded.records {
            let Some((table_name, _)) = tables.get_key_value(name.as_str()) else {
                return Err(WalError::UnknownTable { path, table: name });
            };
            let (first_key, batch) =
                PreparedBatch::from_image(image).map_err(|e| WalError::Corrupt {
                    path: path.clone(),
                    problem: format!("a record of table {name:?} does not hold together: {e}"),
                })?;
            by_table
                .entry(table_name.as_str())
                .or_default()
                .push((first_key, batch));
        }
    }
    for (name, mut batches) in by_table {
        let Some(table) = tables.get(name) else {
            continue;
        };
        batches.sort_by_key(|(first, _)| *first);
        let held = table.stats().next_key;
        for (first_key, batch) in batches {
            if first_key < held {
                done.covered += 1;
                continue;
            }
            let inserted = table.insert_now(&batch).map_err(|e| WalError::Corrupt {
                path: dir.to_path_buf(),
                problem: format!("a batch of table {name:?} at key {first_key}: {e}"),
            })?;
            done.batches += 1;
            done.transitions += u64::from(inserted.inserted);
        }
    }
    Ok(done)
}

/// Renames every segment of `dir` aside (`*.log.skipped`), so a server
/// started without restoring never replays them later. Kept, not deleted.
pub fn set_aside(dir: &Path) -> Result<usize, WalError> {
    if !dir.exists() {
        return Ok(0);
    }
    let found = segments(dir)?;
    for (_, path) in &found {
        let aside = path.with_extension("log.skipped");
        fs::rename(path, &aside).map_err(io(path, "setting aside"))?;
    }
    Ok(found.len())
}

type Reply = tokio::sync::oneshot::Sender<Result<Inserted, WalError>>;

/// A batch on its way to the log, with its room in its table.
struct Record {
    reservation: Reservation,
    batch: PreparedBatch,
    reply: Reply,
}

enum Msg {
    /// A batch to frame and write; stored and answered once durable, or
    /// answered with the failure (its reservation dropped). Boxed: a
    /// record is some 280 bytes, a rotation a channel.
    Record(Box<Record>),
    /// Seal the current segment; answers the last sealed sequence number.
    Rotate(mpsc::Sender<u64>),
}

/// A batch on its way to disk and then into its table: wait on it (async)
/// or block on it.
#[derive(Debug)]
pub struct Pending(tokio::sync::oneshot::Receiver<Result<Inserted, WalError>>);

impl Pending {
    /// Waits until the record is durable and the batch stored, or the
    /// write failed (nothing stored).
    pub async fn durable(self) -> Result<Inserted, WalError> {
        self.0.await.unwrap_or(Err(WalError::Stopped))
    }

    /// The same, blocking the thread (not on an async runtime's thread).
    pub fn wait_durable(self) -> Result<Inserted, WalError> {
        self.0.blocking_recv().unwrap_or(Err(WalError::Stopped))
    }

    /// The answer if it has come, without waiting.
    pub fn try_durable(&mut self) -> Option<Result<Inserted, WalError>> {
        use tokio::sync::oneshot::error::TryRecvError;
        match self.0.try_recv() {
            Ok(result) => Some(result),
            Err(TryRecvError::Empty) => None,
            Err(TryRecvError::Closed) => Some(Err(WalError::Stopped)),
        }
    }
}

/// The log of one server: the writer thread and what inserts need of it.
#[derive(Debug)]
pub struct Wal {
    dir: PathBuf,
    sender: Mutex<Option<mpsc::Sender<Msg>>>,
    failed: Arc<Mutex<Option<(Instant, String)>>>,
    thread: Mutex<Option<JoinHandle<()>>>,
}

impl Wal {
    /// Opens the log in `config.dir` (created if missing) and starts its
    /// writer. New records go to a new segment after the ones there.
    pub fn open(config: WalConfig, metrics: ReplayMetrics) -> Result<Self, WalError> {
        fs::create_dir_all(&config.dir).map_err(io(&config.dir, "creating the folder"))?;
        let next_seq = segments(&config.dir)?.last().map_or(1, |(s, _)| s + 1);
        let failed = Arc::new(Mutex::new(None));
        let (tx, rx) = mpsc::channel();
        let mut writer = Writer {
            dir: config.dir.clone(),
            sync_interval: config.sync_interval,
            sync_bytes: config.sync_bytes.max(1),
            next_seq,
            current: None,
            failed: failed.clone(),
            metrics,
        };
        let thread = std::thread::Builder::new()
            .name("replay-wal".to_owned())
            .spawn(move || writer.run(&rx))
            .map_err(io(&config.dir, "starting the writer thread"))?;
        Ok(Self {
            dir: config.dir,
            sender: Mutex::new(Some(tx)),
            failed,
            thread: Mutex::new(Some(thread)),
        })
    }

    /// Its folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Whether an insert may go ahead: not within a second of a failed
    /// write. A write that fails (a full disk) cuts the segment back to its
    /// last whole record, seals it and fails every insert of its group;
    /// then inserts are refused here for a second, and the next one tries
    /// again. Records already written are never rewritten. Call it before
    /// the table changes, so a refused insert leaves nothing behind.
    pub fn check_writable(&self) -> Result<(), WalError> {
        match &*self.failed.lock() {
            Some((at, cause)) if at.elapsed() < RETRY_AFTER => Err(WalError::Unavailable {
                ago: at.elapsed(),
                cause: cause.clone(),
            }),
            _ => Ok(()),
        }
    }

    /// Queues `batch`, which `reservation` holds room for, to be logged
    /// and then stored in the reservation's table; wait on the answer
    /// before acknowledging the insert. The batch is stored only if its
    /// record is durable; otherwise the reservation is dropped.
    pub fn append(&self, reservation: Reservation, batch: PreparedBatch) -> Pending {
        let (reply, rx) = tokio::sync::oneshot::channel();
        let record = Record {
            reservation,
            batch,
            reply,
        };
        if let Some(sender) = &*self.sender.lock() {
            // A send fails only when the writer is gone; the dropped record
            // then gives its room back and its reply answers `Stopped`.
            let _ = sender.send(Msg::Record(Box::new(record)));
        }
        Pending(rx)
    }

    /// Seals the current segment once every record queued before is
    /// written; returns the last sealed sequence number (segments up to it
    /// hold only records queued before this call). Blocking.
    pub fn rotate(&self) -> Result<u64, WalError> {
        let (tx, rx) = mpsc::channel();
        {
            let sender = self.sender.lock();
            let sender = sender.as_ref().ok_or(WalError::Stopped)?;
            sender
                .send(Msg::Rotate(tx))
                .map_err(|_| WalError::Stopped)?;
        }
        rx.recv().map_err(|_| WalError::Stopped)
    }

    /// Deletes the segments up to `seq` (a snapshot now holds them).
    pub fn delete_through(&self, seq: u64) -> Result<usize, WalError> {
        let mut deleted = 0;
        for (s, path) in segments(&self.dir)? {
            if s <= seq {
                fs::remove_file(&path).map_err(io(&path, "deleting"))?;
                deleted += 1;
            }
        }
        if deleted > 0 {
            sync_dir(&self.dir)?;
        }
        Ok(deleted)
    }

    /// Stops the writer once every queued record is written.
    pub fn close(&self) {
        self.sender.lock().take();
        if let Some(thread) = self.thread.lock().take()
            && thread.join().is_err()
        {
            tracing::error!("the write-ahead log's writer panicked");
        }
    }
}

impl Drop for Wal {
    fn drop(&mut self) {
        self.close();
    }
}

/// The writer thread's state. Whatever arrived while the last fsync ran,
/// or up to `sync_interval` / `sync_bytes` more, shares one fsync; once it
/// returns the writer stores the group's batches in their tables, in log
/// order, and answers every insert of the group.
///
/// The writer gives the keys as it frames a record: its table's next key,
/// after the group's earlier records. It is the only one storing batches
/// while the log is on and stores each group in the order it wrote it, so
/// the keys in the log are the keys in the table, and the replay at start
/// gives them the same keys again. A failed group is stored nowhere and
/// takes no keys: the next group's records take them, and the log has no
/// gap. (Keys handed out before the write would leave a gap in the table's
/// ring wherever a write failed.)
struct Writer {
    dir: PathBuf,
    sync_interval: Duration,
    sync_bytes: usize,
    next_seq: u64,
    /// The open segment: sequence number, file, length of its whole records.
    current: Option<(u64, File, u64)>,
    failed: Arc<Mutex<Option<(Instant, String)>>>,
    metrics: ReplayMetrics,
}

/// The records of one group: their bytes, framed, and what the writer
/// stores and answers once they are durable.
#[derive(Default)]
struct Group {
    bytes: Vec<u8>,
    records: Vec<(Record, u64)>,
    /// Per table, the key the group's next record of it takes.
    next_keys: BTreeMap<String, u64>,
}

impl Group {
    /// Frames a record into the group, or returns a rotation's reply.
    fn take(&mut self, msg: Msg) -> Option<mpsc::Sender<u64>> {
        let record = match msg {
            Msg::Record(record) => *record,
            Msg::Rotate(reply) => return Some(reply),
        };
        let table = record.reservation.table();
        let next = self
            .next_keys
            .entry(table.name().to_owned())
            .or_insert_with(|| table.next_key());
        let first_key = *next;
        *next += record.batch.len() as u64;
        encode_record(
            &mut self.bytes,
            table.name(),
            &record.batch.to_image(first_key),
        );
        self.records.push((record, first_key));
        None
    }

    /// Stores every batch of the group in its table, in log order, if the
    /// group is durable, and answers each insert; empties the group.
    fn finish(&mut self, written: &Result<(), WalError>) {
        for (record, first_key) in self.records.drain(..) {
            let Record {
                reservation,
                batch,
                reply,
            } = record;
            let answer = match written {
                Ok(()) => {
                    let table = reservation.table().clone();
                    let stored = reservation.store(&batch);
                    if stored.first_key != first_key {
                        tracing::error!(
                            table = table.name(),
                            logged = first_key,
                            stored = stored.first_key,
                            "a batch was stored at other keys than its log record says: \
                             something inserted into the table beside the log's writer"
                        );
                    }
                    Ok(stored)
                }
                Err(e) => {
                    drop(reservation);
                    Err(e.clone())
                }
            };
            let _ = reply.send(answer);
        }
        self.bytes.clear();
        self.next_keys.clear();
    }
}

impl Writer {
    fn run(&mut self, rx: &mpsc::Receiver<Msg>) {
        let mut group = Group::default();
        while let Ok(first) = rx.recv() {
            let mut rotate = group.take(first);
            // Whatever is already queued shares this fsync; then wait up to
            // the interval for more, unless the group is full.
            let deadline = Instant::now() + self.sync_interval;
            while rotate.is_none() && group.bytes.len() < self.sync_bytes {
                let next = match rx.try_recv() {
                    Ok(m) => Some(m),
                    Err(mpsc::TryRecvError::Disconnected) => None,
                    Err(mpsc::TryRecvError::Empty) => {
                        let left = deadline.saturating_duration_since(Instant::now());
                        if left.is_zero() {
                            None
                        } else {
                            rx.recv_timeout(left).ok()
                        }
                    }
                };
                let Some(msg) = next else { break };
                rotate = group.take(msg);
            }
            if !group.records.is_empty() {
                let written = self.write_group(&group.bytes, group.records.len());
                // Stored before a rotation is answered: every record of a
                // sealed segment is in its table when a snapshot copies it.
                group.finish(&written);
            }
            if let Some(reply) = rotate {
                let sealed = match self.current.take() {
                    Some((seq, _, _)) => seq,
                    None => self.next_seq - 1,
                };
                let _ = reply.send(sealed);
            }
        }
    }

    /// Writes and fsyncs one group; on failure cuts the segment back to
    /// its last whole record and seals it.
    fn write_group(&mut self, bytes: &[u8], records: usize) -> Result<(), WalError> {
        let start = Instant::now();
        let result = self.try_write(bytes);
        match &result {
            Ok(()) => {
                self.metrics.wal_records.inc_by(records as u64);
                self.metrics.wal_bytes.inc_by(bytes.len() as u64);
                self.metrics
                    .wal_sync_seconds
                    .observe(start.elapsed().as_secs_f64());
                *self.failed.lock() = None;
            }
            Err(e) => {
                self.metrics.wal_errors.inc();
                tracing::error!(error = %e, records, "write-ahead log write failed; those inserts fail");
                if let Some((seq, file, good)) = self.current.take()
                    && let Err(cut) = file.set_len(good)
                {
                    tracing::warn!(seq, error = %cut,
                        "cannot cut the segment back; its torn tail is skipped when read");
                }
                *self.failed.lock() = Some((Instant::now(), e.to_string()));
            }
        }
        result
    }

    fn try_write(&mut self, bytes: &[u8]) -> Result<(), WalError> {
        if self.current.is_none() {
            let seq = self.next_seq;
            let path = self.dir.join(format!("{PREFIX}{seq:010}{SUFFIX}"));
            let mut file = OpenOptions::new()
                .create_new(true)
                .append(true)
                .open(&path)
                .map_err(io(&path, "creating"))?;
            self.next_seq += 1;
            let made = file
                .write_all(&segment_header())
                .and_then(|()| file.sync_all())
                .map_err(io(&path, "writing the header"))
                .and_then(|()| sync_dir(&self.dir));
            if let Err(e) = made {
                let _ = fs::remove_file(&path);
                return Err(e);
            }
            self.current = Some((seq, file, HEADER_LEN as u64));
        }
        let Some((seq, file, good)) = &mut self.current else {
            return Err(WalError::Stopped);
        };
        let path = self.dir.join(format!("{PREFIX}{seq:010}{SUFFIX}"));
        file.write_all(bytes)
            .and_then(|()| file.sync_data())
            .map_err(io(&path, "appending"))?;
        *good += bytes.len() as u64;
        Ok(())
    }
}
