//! `[replay]`: the replay server's table, rate limiter, limits and
//! snapshots.

use std::net::SocketAddr;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::Checks;

/// How importance weights are normalized.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum WeightNormalization {
    /// Divide by the largest weight any item of the table could get (that
    /// of the lowest priority), so weights are comparable across batches.
    #[default]
    Table,
    /// Divide by the largest weight in the sampled batch (the PER paper's
    /// practice).
    Batch,
}

/// The replay server (`crossroads replay`): one prioritized table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ReplayConfig {
    /// gRPC address to serve on; port 0 picks a free port.
    pub listen: SocketAddr,
    /// Name of the table; requests naming another table are rejected.
    pub table: String,
    /// Items kept; the oldest is evicted first (FIFO) when full.
    /// 1 to 100,000,000.
    pub capacity: u64,
    /// Priority exponent: items are sampled with probability p^alpha / sum;
    /// 0 samples uniformly. 0 to 1.
    pub alpha: f64,
    /// Priorities below this are raised to it before the exponent, so no
    /// item becomes unsampleable and weights stay finite. Above 0.
    pub min_priority: f64,
    /// Importance weights divided by the table's or the batch's largest.
    pub weight_normalization: WeightNormalization,
    /// Items inserted before the first sample is allowed (counted over the
    /// table's life, so a value above `capacity` only delays sampling).
    pub min_size_to_sample: u64,
    /// Target samples per inserted item (the learner neither overfits a
    /// small buffer nor falls behind); 0 turns the ratio off.
    pub samples_per_insert: f64,
    /// Samples per insert at the start of the run, moving linearly to
    /// `samples_per_insert` over `ratio_ramp`: fresh experience while the
    /// network learns the most, more reuse of it later. Unset keeps
    /// `samples_per_insert` throughout. Above 0; needs `samples_per_insert`
    /// above 0.
    pub early_samples_per_insert: Option<f64>,
    /// Items sampled (learner updates x `learner.batch_size`) when the
    /// ratio leaves `early_samples_per_insert` and when it reaches
    /// `samples_per_insert`: `[from, to]`, from at most to.
    pub ratio_ramp: [u64; 2],
    /// How far, in samples, the ratio may drift either way before inserts
    /// or samples wait. At least max(1, samples_per_insert,
    /// early_samples_per_insert) when the ratio is on.
    pub rate_tolerance: f64,
    /// Longest an insert waits for the rate limiter, milliseconds.
    pub insert_timeout_ms: u64,
    /// Longest a sample waits for the rate limiter when the request does
    /// not say, milliseconds.
    pub sample_timeout_ms: u64,
    /// Largest gRPC message accepted, bytes (64 KiB to 1 GiB).
    pub max_message_bytes: usize,
    /// Largest batch accepted, transitions.
    pub max_batch_transitions: u32,
    /// Largest sample or priority update, items.
    pub max_sample_batch: u32,
    /// Seed of the sampler's random numbers.
    pub seed: u64,
    /// Where snapshots are written and restored from; none disables them.
    pub snapshot_dir: Option<PathBuf>,
    /// Seconds between periodic snapshots; 0 writes them only on shutdown
    /// and on request.
    pub snapshot_interval_secs: u64,
    /// Snapshots kept (the newest good ones); at least 1.
    pub snapshot_keep: u32,
    /// Whether to restore the newest good snapshot at start (and replay
    /// the write-ahead log on top of it).
    pub restore: bool,
    /// Whether inserts are acknowledged only once they are in a write-ahead
    /// log on disk (`<snapshot_dir>/wal`, fsynced in groups), so that an
    /// acknowledged transition survives a kill -9 of the server. Needs
    /// `snapshot_dir`; without one there is nothing to recover from.
    pub wal: bool,
    /// Longest an insert waits for others to share its fsync,
    /// milliseconds (0: only those already queued share it). 0 to 1000.
    pub wal_sync_ms: u64,
    /// A group of log records this large is written and fsynced at once,
    /// bytes. 4 KiB to 1 GiB.
    pub wal_sync_bytes: usize,
    /// Whether to take batches over iceoryx2 shared memory from actors on
    /// this host (beside gRPC).
    pub shm_ingest: bool,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 50051)),
            table: "transitions".to_owned(),
            capacity: 1_000_000,
            alpha: 0.6,
            min_priority: 1e-6,
            weight_normalization: WeightNormalization::Table,
            min_size_to_sample: 1_000,
            samples_per_insert: 0.0,
            early_samples_per_insert: None,
            ratio_ramp: [0, 0],
            rate_tolerance: 1_000.0,
            insert_timeout_ms: 30_000,
            sample_timeout_ms: 10_000,
            max_message_bytes: 64 << 20,
            max_batch_transitions: 16_384,
            max_sample_batch: 4_096,
            seed: 1,
            snapshot_dir: None,
            snapshot_interval_secs: 300,
            snapshot_keep: 2,
            restore: true,
            wal: true,
            wal_sync_ms: 1,
            wal_sync_bytes: 4 << 20,
            shm_ingest: true,
        }
    }
}

impl ReplayConfig {
    /// Range and relation checks, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = Checks::new("replay");
        problems.check(
            !self.table.is_empty() && self.table.len() <= 64,
            "table",
            format!("must be 1 to 64 characters, got {:?}", self.table),
        );
        problems.within("capacity", self.capacity, 1..=100_000_000);
        problems.within("alpha", self.alpha, 0.0..=1.0);
        problems.check(
            self.min_priority > 0.0 && self.min_priority.is_finite(),
            "min_priority",
            format!("must be finite and above 0, got {}", self.min_priority),
        );
        problems.check(
            self.samples_per_insert >= 0.0 && self.samples_per_insert.is_finite(),
            "samples_per_insert",
            format!(
                "must be finite and at least 0 (0 = off), got {}",
                self.samples_per_insert
            ),
        );
        if let Some(early) = self.early_samples_per_insert {
            problems.check(
                early > 0.0 && early.is_finite(),
                "early_samples_per_insert",
                format!("must be finite and above 0, got {early}"),
            );
            problems.check(
                self.samples_per_insert > 0.0,
                "early_samples_per_insert",
                "needs replay.samples_per_insert above 0 (the ratio it moves to)".to_owned(),
            );
        }
        problems.check(
            self.ratio_ramp[0] <= self.ratio_ramp[1],
            "ratio_ramp",
            format!(
                "must be [from, to] with from at most to, got {:?}",
                self.ratio_ramp
            ),
        );
        let early = self.early_samples_per_insert.unwrap_or(0.0);
        let min_tolerance = self.samples_per_insert.max(early).max(1.0);
        problems.check(
            self.samples_per_insert == 0.0
                || (self.rate_tolerance >= min_tolerance && self.rate_tolerance.is_finite()),
            "rate_tolerance",
            format!(
                "must be at least max(1, replay.samples_per_insert, replay.early_samples_per_insert) = {min_tolerance}, got {}",
                self.rate_tolerance
            ),
        );
        for (key, value) in [
            ("insert_timeout_ms", self.insert_timeout_ms),
            ("sample_timeout_ms", self.sample_timeout_ms),
        ] {
            problems.within(key, value, 1..=3_600_000);
        }
        problems.within(
            "max_message_bytes",
            self.max_message_bytes,
            64 << 10..=1 << 30,
        );
        problems.check(
            self.max_batch_transitions >= 1,
            "max_batch_transitions",
            "must be at least 1".to_owned(),
        );
        problems.within("max_sample_batch", self.max_sample_batch, 1..=1 << 20);
        problems.within("wal_sync_ms", self.wal_sync_ms, 0..=1000);
        problems.within("wal_sync_bytes", self.wal_sync_bytes, 4 << 10..=1 << 30);
        problems.check(
            self.snapshot_keep >= 1,
            "snapshot_keep",
            "must be at least 1".to_owned(),
        );
        problems.into_vec()
    }
}
