//! The replay server's Prometheus metrics, `crossroads_replay_*`: each is
//! registered in [`ReplayMetrics::new`] with its labels (of `table`,
//! `transport`, `op`, `reason` and `result`, those that apply) and a help
//! text that says what it counts; `crossroads_replay_snapshot_age_seconds`
//! is computed at scrape. docs/roles.md, "Metrics of each role", lists them
//! for readers.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{SystemTime, UNIX_EPOCH};

use crossroads_types::RejectReason;
use prometheus::core::{Collector, Desc};
use prometheus::proto::MetricFamily;
use prometheus::{
    Gauge, Histogram, HistogramOpts, HistogramVec, IntCounter, IntCounterVec, IntGauge,
    IntGaugeVec, Opts, Registry,
};

/// Every replay metric of the process. Cheap to clone (handles).
#[derive(Debug, Clone)]
pub struct ReplayMetrics {
    size: IntGaugeVec,
    capacity: IntGaugeVec,
    bytes: IntGaugeVec,
    inserts: IntCounterVec,
    insert_batches: IntCounterVec,
    samples: IntCounterVec,
    priority_updates: IntCounterVec,
    ignored_updates: IntCounterVec,
    rejections: IntCounterVec,
    waits: IntCounterVec,
    wait_seconds: HistogramVec,
    /// Snapshots written (`ok`) or failed (`error`).
    pub snapshots: IntCounterVec,
    /// Duration of the last snapshot written.
    pub snapshot_duration: Gauge,
    /// Size of the last snapshot written.
    pub snapshot_bytes: IntGauge,
    /// When the last snapshot was written (or restored), Unix ms; 0 if none.
    pub last_snapshot_unix_ms: Arc<AtomicU64>,
    /// Write-ahead-log records (inserted batches) made durable.
    pub wal_records: IntCounter,
    /// Bytes written to the write-ahead log.
    pub wal_bytes: IntCounter,
    /// Time to write and fsync one group of records.
    pub wal_sync_seconds: Histogram,
    /// Groups of records that could not be written (a full disk, say).
    pub wal_errors: IntCounter,
}

impl ReplayMetrics {
    /// Creates the metrics and registers them in `registry`, if given.
    pub fn new(registry: Option<&Registry>) -> Result<Self, prometheus::Error> {
        let gauge = |name: &str, help: &str, labels: &[&str]| {
            IntGaugeVec::new(Opts::new(name, help), labels)
        };
        let counter = |name: &str, help: &str, labels: &[&str]| {
            IntCounterVec::new(Opts::new(name, help), labels)
        };
        let m = Self {
            size: gauge(
                "crossroads_replay_size_items",
                "Items held by the table",
                &["table"],
            )?,
            capacity: gauge(
                "crossroads_replay_capacity_items",
                "Items the table can hold",
                &["table"],
            )?,
            bytes: gauge(
                "crossroads_replay_storage_bytes",
                "Memory held by the table: items, priorities and compact observations",
                &["table"],
            )?,
            inserts: counter(
                "crossroads_replay_inserts_total",
                "Items inserted, by transport (grpc or shm)",
                &["table", "transport"],
            )?,
            insert_batches: counter(
                "crossroads_replay_insert_batches_total",
                "Batches inserted, by transport (grpc or shm)",
                &["table", "transport"],
            )?,
            samples: counter(
                "crossroads_replay_samples_total",
                "Items sampled",
                &["table"],
            )?,
            priority_updates: counter(
                "crossroads_replay_priority_updates_total",
                "Priorities updated",
                &["table"],
            )?,
            ignored_updates: counter(
                "crossroads_replay_priority_updates_ignored_total",
                "Priority updates for items evicted since they were sampled",
                &["table"],
            )?,
            rejections: counter(
                "crossroads_replay_rejections_total",
                "Inputs rejected at the boundary, by reason",
                &["reason"],
            )?,
            waits: counter(
                "crossroads_replay_rate_limiter_waits_total",
                "Inserts or samples that had to wait for the rate limiter",
                &["table", "op"],
            )?,
            wait_seconds: HistogramVec::new(
                HistogramOpts::new(
                    "crossroads_replay_rate_limiter_wait_seconds",
                    "How long inserts or samples that waited for the rate limiter waited",
                )
                .buckets(vec![0.001, 0.01, 0.1, 0.5, 1.0, 5.0, 30.0]),
                &["table", "op"],
            )?,
            snapshots: counter(
                "crossroads_replay_snapshots_total",
                "Snapshots written (ok) or failed (error)",
                &["result"],
            )?,
            snapshot_duration: Gauge::new(
                "crossroads_replay_snapshot_duration_seconds",
                "Time the last snapshot took, from copy to rename",
            )?,
            snapshot_bytes: IntGauge::new(
                "crossroads_replay_snapshot_bytes",
                "Size of the last snapshot written",
            )?,
            last_snapshot_unix_ms: Arc::new(AtomicU64::new(0)),
            wal_records: IntCounter::new(
                "crossroads_replay_wal_records_total",
                "Inserted batches made durable in the write-ahead log",
            )?,
            wal_bytes: IntCounter::new(
                "crossroads_replay_wal_bytes_total",
                "Bytes written to the write-ahead log",
            )?,
            wal_sync_seconds: Histogram::with_opts(
                HistogramOpts::new(
                    "crossroads_replay_wal_sync_seconds",
                    "Time to write and fsync one group of write-ahead-log records",
                )
                .buckets(vec![0.0005, 0.001, 0.002, 0.005, 0.01, 0.05, 0.25, 1.0]),
            )?,
            wal_errors: IntCounter::new(
                "crossroads_replay_wal_errors_total",
                "Groups of write-ahead-log records that could not be written (their inserts failed)",
            )?,
        };
        for reason in RejectReason::ALL {
            m.rejections.with_label_values(&[reason.as_str()]);
        }
        for result in ["ok", "error"] {
            m.snapshots.with_label_values(&[result]);
        }
        if let Some(r) = registry {
            r.register(Box::new(m.size.clone()))?;
            r.register(Box::new(m.capacity.clone()))?;
            r.register(Box::new(m.bytes.clone()))?;
            r.register(Box::new(m.inserts.clone()))?;
            r.register(Box::new(m.insert_batches.clone()))?;
            r.register(Box::new(m.samples.clone()))?;
            r.register(Box::new(m.priority_updates.clone()))?;
            r.register(Box::new(m.ignored_updates.clone()))?;
            r.register(Box::new(m.rejections.clone()))?;
            r.register(Box::new(m.waits.clone()))?;
            r.register(Box::new(m.wait_seconds.clone()))?;
            r.register(Box::new(m.snapshots.clone()))?;
            r.register(Box::new(m.snapshot_duration.clone()))?;
            r.register(Box::new(m.snapshot_bytes.clone()))?;
            r.register(Box::new(SnapshotAge::new(m.last_snapshot_unix_ms.clone())?))?;
            r.register(Box::new(m.wal_records.clone()))?;
            r.register(Box::new(m.wal_bytes.clone()))?;
            r.register(Box::new(m.wal_sync_seconds.clone()))?;
            r.register(Box::new(m.wal_errors.clone()))?;
        }
        Ok(m)
    }

    /// Metrics registered nowhere (tests, benchmarks).
    pub fn unregistered() -> Self {
        // Creating metrics with fixed, valid names cannot fail.
        #[allow(clippy::expect_used)]
        Self::new(None).expect("static metric definitions are valid")
    }

    /// Handles bound to one table.
    pub fn table(&self, table: &str) -> TableMetrics {
        TableMetrics {
            size: self.size.with_label_values(&[table]),
            capacity: self.capacity.with_label_values(&[table]),
            bytes: self.bytes.with_label_values(&[table]),
            samples: self.samples.with_label_values(&[table]),
            priority_updates: self.priority_updates.with_label_values(&[table]),
            ignored_updates: self.ignored_updates.with_label_values(&[table]),
            insert_waits: self.waits.with_label_values(&[table, "insert"]),
            sample_waits: self.waits.with_label_values(&[table, "sample"]),
            insert_wait_seconds: self.wait_seconds.with_label_values(&[table, "insert"]),
            sample_wait_seconds: self.wait_seconds.with_label_values(&[table, "sample"]),
            grpc_inserts: self.inserts.with_label_values(&[table, "grpc"]),
            shm_inserts: self.inserts.with_label_values(&[table, "shm"]),
            grpc_batches: self.insert_batches.with_label_values(&[table, "grpc"]),
            shm_batches: self.insert_batches.with_label_values(&[table, "shm"]),
        }
    }

    /// Counts one rejected input.
    pub fn reject(&self, reason: RejectReason) {
        self.rejections.with_label_values(&[reason.as_str()]).inc();
    }

    /// Rejections by reason label, for the Info call.
    pub fn rejections(&self) -> Vec<(&'static str, u64)> {
        RejectReason::ALL
            .iter()
            .map(|r| {
                (
                    r.as_str(),
                    self.rejections.with_label_values(&[r.as_str()]).get(),
                )
            })
            .collect()
    }

    /// Records a snapshot just written (or restored).
    pub fn snapshot_done(&self) {
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_millis() as u64)
            .unwrap_or(0);
        self.last_snapshot_unix_ms.store(now, Ordering::SeqCst);
    }
}

/// One table's metric handles.
#[derive(Debug, Clone)]
pub struct TableMetrics {
    /// Items held.
    pub size: IntGauge,
    /// Capacity.
    pub capacity: IntGauge,
    /// Memory held.
    pub bytes: IntGauge,
    /// Items sampled.
    pub samples: IntCounter,
    /// Priorities updated.
    pub priority_updates: IntCounter,
    /// Updates ignored.
    pub ignored_updates: IntCounter,
    insert_waits: IntCounter,
    sample_waits: IntCounter,
    insert_wait_seconds: Histogram,
    sample_wait_seconds: Histogram,
    grpc_inserts: IntCounter,
    shm_inserts: IntCounter,
    grpc_batches: IntCounter,
    shm_batches: IntCounter,
}

impl TableMetrics {
    /// Handles registered nowhere.
    pub fn unregistered(table: &str) -> Self {
        ReplayMetrics::unregistered().table(table)
    }

    /// Waits counter of `op` (`insert` or `sample`).
    pub fn waits(&self, op: &str) -> &IntCounter {
        if op == "insert" {
            &self.insert_waits
        } else {
            &self.sample_waits
        }
    }

    /// Wait-time histogram of `op`.
    pub fn wait_seconds(&self, op: &str) -> &Histogram {
        if op == "insert" {
            &self.insert_wait_seconds
        } else {
            &self.sample_wait_seconds
        }
    }

    /// Counts an inserted batch of `items` that came over `transport`.
    pub fn inserted(&self, transport: Transport, items: u64) {
        let (i, b) = match transport {
            Transport::Grpc => (&self.grpc_inserts, &self.grpc_batches),
            Transport::Shm => (&self.shm_inserts, &self.shm_batches),
        };
        i.inc_by(items);
        b.inc();
    }
}

/// How a batch arrived.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// gRPC streaming insert.
    Grpc,
    /// iceoryx2 shared memory.
    Shm,
}

/// `crossroads_replay_snapshot_age_seconds`, computed when scraped.
#[derive(Debug)]
struct SnapshotAge {
    last: Arc<AtomicU64>,
    gauge: Gauge,
}

impl SnapshotAge {
    fn new(last: Arc<AtomicU64>) -> Result<Self, prometheus::Error> {
        Ok(Self {
            last,
            gauge: Gauge::new(
                "crossroads_replay_snapshot_age_seconds",
                "Seconds since the last snapshot was written or restored; -1 if none",
            )?,
        })
    }
}

impl Collector for SnapshotAge {
    fn desc(&self) -> Vec<&Desc> {
        self.gauge.desc()
    }

    fn collect(&self) -> Vec<MetricFamily> {
        let last = self.last.load(Ordering::SeqCst);
        let age = if last == 0 {
            -1.0
        } else {
            let now = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_millis() as u64)
                .unwrap_or(last);
            now.saturating_sub(last) as f64 / 1000.0
        };
        self.gauge.set(age);
        self.gauge.collect()
    }
}
