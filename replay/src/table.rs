//! A prioritized replay table: items in a FIFO ring, their priorities in a
//! [`SumTree`], their observations in an [`ObservationStore`], admission by
//! a [`RateLimiter`].
//!
//! Items are keyed by insertion order (key `k` is the k-th item ever
//! inserted), so a key names one item forever: once evicted, its key is
//! simply no longer in `[oldest, next)` and priority updates for it are
//! ignored and counted. Sampling draws items with probability
//! `p_i^alpha / sum_j p_j^alpha` (alpha 0: uniform) and returns importance
//! weights `(N * P(i))^-beta` divided by the largest weight of the table or
//! of the batch.
//!
//! Every operation holds the table's lock only for its in-memory part:
//! batches are encoded before ([`PreparedBatch`]), sampled observations
//! decoded after, and waits for the rate limiter happen with no lock held,
//! so a caller that goes away mid-wait (its future dropped) leaves nothing
//! behind.
//! Each public method of [`Table`] states its contract, after Reverb's
//! `table.h`: whether it blocks, its timeout, and what it mutates.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crossroads_common::Shutdown;
use crossroads_config::{ReplayConfig, WeightNormalization};
use crossroads_types::batch::{
    BatchError, MAX_OBSERVATION_LEN, ObservationPool, RejectReason, Transition, TransitionBatch,
    check_priorities,
};
use crossroads_types::{
    Columns, ObservationEncoding, ObservationLayout, PrioritiesUpdated, Sample,
};
use parking_lot::Mutex;
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use tokio::sync::Notify;

use crate::compact;
use crate::metrics::TableMetrics;
use crossroads_transport::grpc::{RateLimiterInfo, TableInfo};

use crate::rate_limiter::{RateLimiter, RateLimiterConfig, RatioRamp};
use crate::storage::{ObservationStore, content_hash};
use crate::sum_tree::SumTree;
use crate::table_image::check_image;

pub use crate::prepared_batch::PreparedBatch;
pub use crate::table_image::TableImage;

/// A table's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct TableConfig {
    /// Name that requests use.
    pub name: String,
    /// Items kept.
    pub capacity: usize,
    /// Priority exponent.
    pub alpha: f64,
    /// Floor applied to priorities before the exponent.
    pub min_priority: f64,
    /// Largest weight of the table or of the batch.
    pub normalization: WeightNormalization,
    /// Seed of the sampler.
    pub seed: u64,
    /// When inserts and samples may proceed.
    pub limiter: RateLimiterConfig,
}

impl TableConfig {
    /// The table the `[replay]` section describes.
    pub fn from_config(c: &ReplayConfig) -> Self {
        Self {
            name: c.table.clone(),
            capacity: c.capacity as usize,
            alpha: c.alpha,
            min_priority: c.min_priority,
            normalization: c.weight_normalization,
            seed: c.seed,
            limiter: RateLimiterConfig {
                min_size_to_sample: c.min_size_to_sample,
                samples_per_insert: c.samples_per_insert,
                tolerance: c.rate_tolerance,
                ramp: c.early_samples_per_insert.map(|early| RatioRamp {
                    early,
                    from: c.ratio_ramp[0],
                    to: c.ratio_ramp[1],
                }),
            },
        }
    }
}

/// Why a table call failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TableError {
    /// The input is invalid; nothing was changed.
    #[error("{0}")]
    Invalid(#[from] BatchError),
    /// The rate limiter did not allow the call within its timeout.
    #[error("{op} not allowed by the rate limiter within {waited:?} ({state})")]
    Timeout {
        /// `insert` or `sample`.
        op: &'static str,
        /// How long it waited.
        waited: Duration,
        /// The limiter's counts, for the message.
        state: String,
    },
    /// The server is shutting down; nothing was changed.
    #[error("the replay server is shutting down")]
    ShuttingDown,
    /// A stored observation does not decode (only a corrupt restore can
    /// cause this).
    #[error("stored observation {0} is corrupt")]
    Corrupt(u32),
}

/// A batch admitted to a table but not stored yet ([`Table::reserve`]):
/// [`store`](Self::store) puts it in, dropping the reservation gives the
/// room back. Its items count against the rate limiter meanwhile.
#[derive(Debug)]
#[must_use = "a reservation holds back inserts until it is stored or dropped"]
pub struct Reservation {
    table: Arc<Table>,
    items: u64,
    stored: bool,
}

impl Reservation {
    /// The table it holds room in.
    pub fn table(&self) -> &Arc<Table> {
        &self.table
    }

    /// Stores `batch`, the batch reserved; it cannot be refused anymore
    /// (its spec and its room were checked when reserved).
    ///
    /// - Blocks: no.
    /// - Timeout: none.
    /// - Mutates: as [`Table::insert`], without waiting.
    pub fn store(mut self, batch: &PreparedBatch) -> Inserted {
        debug_assert_eq!(batch.len() as u64, self.items, "not the batch reserved");
        let inserted = self.table.store_reserved(self.items, batch);
        self.stored = true;
        inserted
    }
}

impl Drop for Reservation {
    fn drop(&mut self) {
        if !self.stored {
            self.table.release(self.items);
        }
    }
}

/// What an insert did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Inserted {
    /// Items stored.
    pub inserted: u32,
    /// Table size after.
    pub size: u64,
    /// Key of the first item stored.
    pub first_key: u64,
}

/// A table's size, counters and limiter state: what `Info` reports of it
/// (the server adds its rejections and last snapshot), and what only the
/// table knows.
#[derive(Debug, Clone, PartialEq)]
pub struct TableStats {
    /// Name, size, capacity, counters and bytes, as `Info` reports them
    /// (`rate_limiter` is [`Self::limiter`]; `rejections_total` and
    /// `last_snapshot_unix_ms` are the server's, empty here).
    pub info: TableInfo,
    /// The rate limiter's settings and state.
    pub limiter: RateLimiterInfo,
    /// Distinct observations held.
    pub observations: u64,
    /// Next key to be given.
    pub next_key: u64,
}

impl TableStats {
    /// What `Info` reports: the counters with the rate limiter.
    pub fn into_info(self) -> TableInfo {
        TableInfo {
            rate_limiter: Some(self.limiter),
            ..self.info
        }
    }
}

#[derive(Debug)]
struct Inner {
    /// The observation layout and action count of every item.
    spec: Option<(ObservationLayout, u32)>,
    tree: SumTree,
    store: ObservationStore,
    /// The ring of items; the index columns hold store ids.
    items: Columns,
    /// Key held by slot 0 of the ring's first lap.
    base_key: u64,
    next_key: u64,
    size: usize,
    rng: Xoshiro256PlusPlus,
    /// Also the count of items ever inserted and sampled.
    limiter: RateLimiter,
    /// Items reserved and not stored yet; they count against the limiter.
    reserved: u64,
    /// Whether `spec` was set by a reservation and no batch is stored
    /// yet: dropping the last reservation then clears it again.
    spec_reserved: bool,
    priority_updates_total: u64,
    ignored_updates_total: u64,
}
/// One prioritized table. Thread-safe (`&self` everywhere); share it in an
/// `Arc`.
///
/// Every method but [`insert`](Self::insert), [`reserve`](Self::reserve)
/// and [`sample`](Self::sample) returns without waiting (it only takes the
/// lock, held for work proportional to its input); those wait for the
/// rate limiter with no lock held, at most their timeout. Each
/// method's doc states what it mutates; the accessors
/// ([`name`](Self::name), [`config`](Self::config),
/// [`metrics`](Self::metrics)) take no lock and mutate nothing. A change
/// of content wakes every waiting call to look again.
#[derive(Debug)]
pub struct Table {
    config: TableConfig,
    inner: Mutex<Inner>,
    changed: Notify,
    metrics: TableMetrics,
}

impl Table {
    /// An empty table. Sets the capacity gauge of `metrics`.
    pub fn new(config: TableConfig, metrics: TableMetrics) -> Self {
        let inner = Inner::new(&config, 0);
        metrics.capacity.set(config.capacity as i64);
        Self {
            config,
            inner: Mutex::new(inner),
            changed: Notify::new(),
            metrics,
        }
    }

    /// Its name.
    pub fn name(&self) -> &str {
        &self.config.name
    }

    /// Its settings.
    pub fn config(&self) -> &TableConfig {
        &self.config
    }

    /// Its metric handles.
    pub fn metrics(&self) -> &TableMetrics {
        &self.metrics
    }

    /// Inserts a batch; all of it is stored or none of it.
    ///
    /// - Blocks: yes, while the rate limiter refuses inserts, without
    ///   holding the lock; dropping the future gives up with nothing
    ///   changed.
    /// - Timeout: `timeout`, then [`TableError::Timeout`]; shutdown ends the
    ///   wait at once with [`TableError::ShuttingDown`].
    /// - Mutates: on success the items (the oldest are evicted when full),
    ///   their observations, the limiter's insert count, the table's spec
    ///   (set by the first batch; a batch of another spec is
    ///   [`TableError::Invalid`]) and the size and bytes gauges; wakes
    ///   waiting samples. An insert that had to wait counts in the
    ///   limiter's and the metrics' waits.
    pub async fn insert(
        &self,
        batch: &PreparedBatch,
        timeout: Duration,
        shutdown: &Shutdown,
    ) -> Result<Inserted, TableError> {
        self.wait_for("insert", timeout, shutdown, |inner, config| {
            inner.check_spec(batch)?;
            if !inner.limiter.can_insert_after(inner.reserved) {
                return Ok(None);
            }
            Ok(Some(inner.insert(config, batch)))
        })
        .await
    }

    /// Admits a batch without storing it: the wait and checks of
    /// [`insert`](Self::insert), after which the batch can only be stored
    /// ([`Reservation::store`]) or given up (the reservation dropped). The
    /// server reserves before it writes a batch to the write-ahead log and
    /// stores it once the record is durable: a batch it does not
    /// acknowledge is never sampled, and a durable one is never refused.
    ///
    /// - Blocks: as [`insert`](Self::insert); items reserved and not yet
    ///   stored count against the rate limiter as if inserted.
    /// - Timeout: as [`insert`](Self::insert).
    /// - Mutates: the reserved count, and the spec when the table has none
    ///   (cleared again if every reservation is dropped before a batch is
    ///   stored); items, counters and gauges change when it is stored.
    pub async fn reserve(
        self: &Arc<Self>,
        batch: &PreparedBatch,
        timeout: Duration,
        shutdown: &Shutdown,
    ) -> Result<Reservation, TableError> {
        self.wait_for("insert", timeout, shutdown, |inner, _| {
            inner.check_spec(batch)?;
            if !inner.limiter.can_insert_after(inner.reserved) {
                return Ok(None);
            }
            inner.reserve(batch);
            Ok(Some(()))
        })
        .await?;
        Ok(self.reservation(batch))
    }

    /// Admits a batch at once, whatever the rate limiter says (for the
    /// last batches drained at shutdown).
    ///
    /// - Blocks: no.
    /// - Timeout: none.
    /// - Mutates: as [`reserve`](Self::reserve), without waiting.
    pub fn reserve_now(self: &Arc<Self>, batch: &PreparedBatch) -> Result<Reservation, TableError> {
        {
            let mut inner = self.inner.lock();
            inner.check_spec(batch)?;
            inner.reserve(batch);
        }
        Ok(self.reservation(batch))
    }

    fn reservation(self: &Arc<Self>, batch: &PreparedBatch) -> Reservation {
        Reservation {
            table: self.clone(),
            items: batch.len() as u64,
            stored: false,
        }
    }

    /// Stores a reserved batch ([`Reservation::store`]).
    fn store_reserved(&self, items: u64, batch: &PreparedBatch) -> Inserted {
        let inserted = {
            let mut inner = self.inner.lock();
            inner.reserved = inner.reserved.saturating_sub(items);
            inner.insert(&self.config, batch)
        };
        self.after_change();
        inserted
    }

    /// Gives back the room of a reservation dropped unstored; wakes waiting
    /// inserts.
    fn release(&self, items: u64) {
        self.inner.lock().release(items);
        self.after_change();
    }

    /// Key the next stored item gets.
    ///
    /// - Blocks: no.
    /// - Timeout: none.
    /// - Mutates: nothing.
    pub fn next_key(&self) -> u64 {
        self.inner.lock().next_key
    }

    /// Inserts a batch at once, whatever the rate limiter says (for the
    /// last batches drained at shutdown).
    ///
    /// - Blocks: no.
    /// - Timeout: none.
    /// - Mutates: as [`insert`](Self::insert), without waiting.
    pub fn insert_now(&self, batch: &PreparedBatch) -> Result<Inserted, TableError> {
        let result = {
            let mut inner = self.inner.lock();
            inner.check_spec(batch)?;
            inner.insert(&self.config, batch)
        };
        self.after_change();
        Ok(result)
    }

    /// Samples `batch_size` items (with replacement) with importance
    /// exponent `beta`; the batch holds each distinct observation once,
    /// sparse. Items are stored validated, so the batch is not checked
    /// again (see [`Sample`]'s parameter).
    ///
    /// - Blocks: yes, while the table is empty or the rate limiter refuses
    ///   samples, without holding the lock; dropping the future gives up
    ///   with nothing changed. A `batch_size` of 0 or a `beta` outside
    ///   [0, 1] fails at once ([`TableError::Invalid`]).
    /// - Timeout: `timeout`, then [`TableError::Timeout`]; shutdown ends the
    ///   wait at once with [`TableError::ShuttingDown`].
    /// - Mutates: the sampler's random state and the limiter's sample
    ///   count (by `batch_size`), and the samples metric (and waits, as an
    ///   insert's); items and priorities are left as they are. Wakes
    ///   waiting inserts.
    pub async fn sample(
        &self,
        batch_size: usize,
        beta: f64,
        timeout: Duration,
        shutdown: &Shutdown,
    ) -> Result<Sample<TransitionBatch>, TableError> {
        if batch_size == 0 {
            return Err(BatchError::new(
                RejectReason::BadRequest,
                "batch_size",
                "must be at least 1",
            )
            .into());
        }
        if !(0.0..=1.0).contains(&beta) {
            return Err(BatchError::new(
                RejectReason::BadRequest,
                "beta",
                format!("{beta} is not in [0, 1]"),
            )
            .into());
        }
        let raw = self
            .wait_for("sample", timeout, shutdown, |inner, config| {
                if !inner.limiter.can_sample() || inner.size == 0 {
                    return Ok(None);
                }
                Ok(Some(inner.sample(config, batch_size, beta)))
            })
            .await?;
        self.metrics.samples.inc_by(batch_size as u64);
        raw.finish()
    }

    /// Sets new priorities of the items `keys` names, `priorities[i]` for
    /// `keys[i]`. Every priority is checked first: one that is negative or
    /// not finite, or lengths that differ, reject the whole request with
    /// nothing changed. Keys no longer held are ignored and counted.
    ///
    /// - Blocks: no.
    /// - Timeout: none.
    /// - Mutates: the priorities (and sampling probabilities) of the items
    ///   held, and the updated and ignored counts and metrics.
    pub fn update_priorities(
        &self,
        keys: &[u64],
        priorities: &[f32],
    ) -> Result<PrioritiesUpdated, TableError> {
        if keys.len() != priorities.len() {
            return Err(BatchError::new(
                RejectReason::LengthMismatch,
                "priorities",
                format!("{} priorities for {} keys", priorities.len(), keys.len()),
            )
            .into());
        }
        check_priorities(priorities, |i| format!("priorities[{i}]"))?;
        let updated = {
            let mut inner = self.inner.lock();
            inner.update(&self.config, keys, priorities)
        };
        self.metrics
            .priority_updates
            .inc_by(u64::from(updated.updated));
        self.metrics
            .ignored_updates
            .inc_by(u64::from(updated.ignored));
        Ok(updated)
    }

    /// Size, counters and limiter state.
    ///
    /// - Blocks: no.
    /// - Timeout: none.
    /// - Mutates: nothing.
    pub fn stats(&self) -> TableStats {
        let inner = self.inner.lock();
        let (inserts_total, samples_total) = inner.limiter.counts();
        let (insert_waits, sample_waits) = inner.limiter.waits();
        let limiter = self.config.limiter;
        TableStats {
            info: TableInfo {
                name: self.config.name.clone(),
                size: inner.size as u64,
                capacity: self.config.capacity as u64,
                inserts_total,
                samples_total,
                priority_updates_total: inner.priority_updates_total,
                ignored_updates_total: inner.ignored_updates_total,
                bytes_stored: inner.bytes() as u64,
                ..TableInfo::default()
            },
            limiter: RateLimiterInfo {
                min_size_to_sample: limiter.min_size_to_sample,
                samples_per_insert: inner.limiter.current_ratio(),
                error_tolerance: limiter.tolerance,
                can_sample: inner.limiter.can_sample() && inner.size > 0,
                can_insert: inner.limiter.can_insert_after(inner.reserved),
                sample_waits_total: sample_waits,
                insert_waits_total: insert_waits,
            },
            observations: inner.store.len() as u64,
            next_key: inner.next_key,
        }
    }

    /// A copy of the whole content, oldest item first.
    ///
    /// - Blocks: no, but holds the lock while it copies every item and
    ///   observation (inserts and samples wait meanwhile).
    /// - Timeout: none.
    /// - Mutates: nothing.
    pub fn image(&self) -> TableImage {
        self.inner.lock().image()
    }

    /// Replaces the content by `image` (restoring a snapshot). When the
    /// image holds more items than the capacity, the oldest are dropped;
    /// returns how many. An image whose items a valid batch could not have
    /// put there (columns of different lengths, no or an invalid spec, an
    /// action, reward, discount or priority a batch may not have, fewer
    /// inserts counted than items held,
    /// observations out of range or not decoding to the spec's length) is
    /// refused with nothing changed: samples are not checked again.
    ///
    /// - Blocks: no; the new content is built without the lock and swapped
    ///   in.
    /// - Timeout: none.
    /// - Mutates: everything: items, observations, keys, counters, the
    ///   limiter's counts (its waits start again from zero), the sampler's
    ///   seed and the gauges; wakes every waiting insert and sample.
    pub fn restore(&self, image: &TableImage) -> Result<usize, BatchError> {
        let obs_len = check_image(image)?;
        let n = image.len();
        // The rate limiter's count: a table never holds more than it took in.
        if image.inserts_total < n as u64 {
            return Err(BatchError::new(
                RejectReason::BadRequest,
                "inserts_total",
                format!("{} inserts for {n} items held", image.inserts_total),
            ));
        }
        // Keys count up from here; a damaged count must not leave them
        // nowhere to go (no table inserts 2^63 items).
        if image.next_key > MAX_RESTORED_KEY {
            return Err(BatchError::new(
                RejectReason::BadRequest,
                "next_key",
                format!(
                    "{} is beyond any key a table hands out (at most {MAX_RESTORED_KEY})",
                    image.next_key
                ),
            ));
        }
        let n_obs = image.observation_offsets.len();
        let keep = n.min(self.config.capacity);
        let skip = n - keep;
        let oldest = image.next_key - n as u64 + skip as u64;
        let mut fresh = Inner::new(&self.config, oldest);
        fresh.spec = image.spec.clone();
        fresh.next_key = oldest;
        let mut ids = Interned::new(n_obs);
        let mut scratch = Vec::new();
        for i in skip..n {
            let Some(mut t) = image.items.get(i) else {
                break;
            };
            for o in [&mut t.observation, &mut t.next_observation] {
                *o = ids.id(&mut fresh.store, *o, |o| {
                    let bytes = image.observation(o).ok_or_else(|| {
                        BatchError::new(
                            RejectReason::ObservationEncoding,
                            format!("observations[{o}]"),
                            "out of the data",
                        )
                    })?;
                    // Samples decode it later without a check of their own.
                    scratch.clear();
                    compact::to_sparse_wire(bytes, obs_len, &mut scratch).map_err(|e| {
                        BatchError::new(
                            RejectReason::ObservationEncoding,
                            format!("observations[{o}]"),
                            e.to_string(),
                        )
                    })?;
                    Ok((bytes, content_hash(bytes)))
                })?;
            }
            fresh.push_item(&self.config, t);
        }
        fresh.priority_updates_total = image.priority_updates_total;
        fresh.ignored_updates_total = image.ignored_updates_total;
        fresh
            .limiter
            .set_counts(image.inserts_total, image.samples_total);
        *self.inner.lock() = fresh;
        self.after_change();
        Ok(skip)
    }

    fn after_change(&self) {
        let (size, bytes) = {
            let inner = self.inner.lock();
            (inner.size, inner.bytes())
        };
        self.metrics.size.set(size as i64);
        self.metrics.bytes.set(bytes as i64);
        self.changed.notify_waiters();
    }

    /// Runs `attempt` under the lock until it returns a value, an error,
    /// the timeout passes or shutdown fires. No lock is held while waiting.
    async fn wait_for<T>(
        &self,
        op: &'static str,
        timeout: Duration,
        shutdown: &Shutdown,
        mut attempt: impl FnMut(&mut Inner, &TableConfig) -> Result<Option<T>, TableError>,
    ) -> Result<T, TableError> {
        let start = Instant::now();
        let deadline = tokio::time::Instant::now() + timeout;
        let mut waited = false;
        loop {
            let notified = self.changed.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            let outcome = {
                let mut inner = self.inner.lock();
                let outcome = attempt(&mut inner, &self.config)?;
                if outcome.is_none() && !waited {
                    match op {
                        "insert" => inner.limiter.insert_waited(),
                        _ => inner.limiter.sample_waited(),
                    }
                }
                outcome
            };
            if let Some(value) = outcome {
                if waited {
                    self.metrics
                        .wait_seconds(op)
                        .observe(start.elapsed().as_secs_f64());
                }
                self.after_change();
                return Ok(value);
            }
            if !waited {
                waited = true;
                self.metrics.waits(op).inc();
            }
            tokio::select! {
                _ = &mut notified => {}
                _ = tokio::time::sleep_until(deadline) => {
                    let inner = self.inner.lock();
                    let (inserts, samples) = inner.limiter.counts();
                    return Err(TableError::Timeout {
                        op,
                        waited: start.elapsed(),
                        state: format!(
                            "{inserts} inserted, {samples} sampled, size {}, min size {}, {} samples per insert",
                            inner.size,
                            self.config.limiter.min_size_to_sample,
                            inner.limiter.current_ratio(),
                        ),
                    });
                }
                _ = shutdown.wait() => return Err(TableError::ShuttingDown),
            }
        }
    }
}

/// The largest next key a restored image may hold.
const MAX_RESTORED_KEY: u64 = 1 << 63;

/// What a sample copied out under the lock; finished into a [`Sample`]
/// without it.
struct RawSample {
    layout: ObservationLayout,
    num_actions: u32,
    keys: Vec<u64>,
    weights: Vec<f32>,
    /// The index columns refer to `observations`.
    columns: Columns,
    /// Store id and compact bytes of each distinct observation.
    observations: Vec<(u32, Vec<u8>)>,
}

impl RawSample {
    fn finish(self) -> Result<Sample<TransitionBatch>, TableError> {
        let len = self.layout.check().unwrap_or(MAX_OBSERVATION_LEN);
        let mut pool = ObservationPool::new(ObservationEncoding::SparseF32);
        let mut wire = Vec::new();
        for (id, bytes) in &self.observations {
            wire.clear();
            compact::to_sparse_wire(bytes, len, &mut wire).map_err(|_| TableError::Corrupt(*id))?;
            pool.push_encoded(&wire);
        }
        Ok(Sample {
            keys: self.keys,
            weights: self.weights,
            batch: TransitionBatch {
                layout: self.layout,
                num_actions: self.num_actions,
                columns: self.columns,
                observations: pool,
            },
        })
    }
}

/// Store ids of the observations of one batch or image: each entry is
/// interned once, and every further use of it takes one more reference.
struct Interned(Vec<Option<u32>>);

impl Interned {
    fn new(entries: usize) -> Self {
        Self(vec![None; entries])
    }

    /// The store id of `entry`, interning what `bytes` gives (the entry's
    /// bytes and content hash) on its first use. `entry` is in range
    /// (checked by the caller).
    fn id<'a, E>(
        &mut self,
        store: &mut ObservationStore,
        entry: u32,
        bytes: impl FnOnce(usize) -> Result<(&'a [u8], u64), E>,
    ) -> Result<u32, E> {
        let slot = &mut self.0[entry as usize];
        if let Some(id) = *slot {
            store.retain(id);
            return Ok(id);
        }
        let (data, hash) = bytes(entry as usize)?;
        let id = store.intern(data, hash);
        *slot = Some(id);
        Ok(id)
    }
}

impl Inner {
    fn new(config: &TableConfig, base_key: u64) -> Self {
        Self {
            spec: None,
            tree: SumTree::new(config.capacity),
            store: ObservationStore::new(),
            items: Columns::default(),
            base_key,
            next_key: base_key,
            size: 0,
            rng: Xoshiro256PlusPlus::seed_from_u64(config.seed),
            limiter: RateLimiter::new(config.limiter),
            reserved: 0,
            spec_reserved: false,
            priority_updates_total: 0,
            ignored_updates_total: 0,
        }
    }

    fn bytes(&self) -> usize {
        self.tree.bytes() + self.store.bytes() + self.items.capacity_bytes()
    }

    /// Checks that `batch` has the table's layout and action count. A
    /// legacy layout, restored from a file of an earlier build, takes any
    /// layout of its kind and length ([`ObservationLayout::reads_as`]).
    fn check_spec(&self, batch: &PreparedBatch) -> Result<(), BatchError> {
        match &self.spec {
            Some((layout, actions))
                if !layout.reads_as(&batch.layout) || *actions != batch.num_actions =>
            {
                Err(BatchError::new(
                    RejectReason::Spec,
                    "layout",
                    format!(
                        "the table holds {layout} with {actions} actions; the batch is {} with {} actions",
                        batch.layout, batch.num_actions
                    ),
                ))
            }
            _ => Ok(()),
        }
    }

    /// Takes the layout of `batch` (checked by [`check_spec`](Self::check_spec))
    /// in place of a legacy one of the same kind and length, so samples carry
    /// the layout the actors send from now on.
    fn adopt_layout(&mut self, batch: &PreparedBatch) {
        if let Some((layout, _)) = &mut self.spec
            && *layout != batch.layout
        {
            tracing::info!(
                legacy = %layout,
                layout = %batch.layout,
                "the table's layout, restored from a file of an earlier build, is now that of its inserts"
            );
            *layout = batch.layout.clone();
        }
    }

    fn leaf(config: &TableConfig, priority: f32) -> f64 {
        f64::from(priority)
            .max(config.min_priority)
            .powf(config.alpha)
    }

    fn slot_of(&self, key: u64, capacity: usize) -> Option<usize> {
        let oldest = self.next_key - self.size as u64;
        (key >= oldest && key < self.next_key)
            .then(|| ((key - self.base_key) % capacity as u64) as usize)
    }

    fn key_of(&self, slot: usize, capacity: usize) -> u64 {
        let newest = self.next_key - 1;
        let newest_slot = ((newest - self.base_key) % capacity as u64) as usize;
        newest - ((newest_slot + capacity - slot) % capacity) as u64
    }

    /// Appends one item (its observations already store ids), evicting the
    /// oldest when full.
    fn push_item(&mut self, config: &TableConfig, item: Transition) {
        let capacity = config.capacity;
        let slot = ((self.next_key - self.base_key) % capacity as u64) as usize;
        if slot < self.items.len() {
            if self.size == capacity {
                self.store.release(self.items.observation_index[slot]);
                self.store.release(self.items.next_observation_index[slot]);
                self.size -= 1;
            }
            self.items.set(slot, item);
        } else {
            self.items.push(item);
        }
        self.tree.set(slot, Self::leaf(config, item.priority));
        self.size += 1;
        self.next_key += 1;
    }

    /// Takes room for `batch` (its spec checked by the caller).
    fn reserve(&mut self, batch: &PreparedBatch) {
        if self.spec.is_none() {
            self.spec = Some((batch.layout.clone(), batch.num_actions));
            self.spec_reserved = true;
        }
        self.adopt_layout(batch);
        self.reserved = self.reserved.saturating_add(batch.len() as u64);
    }

    /// Gives back the room of `items` reserved and not stored.
    fn release(&mut self, items: u64) {
        self.reserved = self.reserved.saturating_sub(items);
        if self.reserved == 0 && self.spec_reserved {
            self.spec = None;
            self.spec_reserved = false;
        }
    }

    fn insert(&mut self, config: &TableConfig, batch: &PreparedBatch) -> Inserted {
        if self.spec.is_none() {
            self.spec = Some((batch.layout.clone(), batch.num_actions));
        }
        self.adopt_layout(batch);
        self.spec_reserved = false;
        let first_key = self.next_key;
        let mut ids = Interned::new(batch.entries.len());
        for i in 0..batch.len() {
            let Some(mut t) = batch.columns.get(i) else {
                break;
            };
            for o in [&mut t.observation, &mut t.next_observation] {
                let Ok(id) = ids.id(&mut self.store, *o, |p| {
                    let (hash, start, end) = batch.entries[p];
                    Ok::<_, Infallible>((&batch.bytes[start..end], hash))
                });
                *o = id;
            }
            self.push_item(config, t);
        }
        self.limiter.inserted(batch.len() as u64);
        Inserted {
            inserted: batch.len() as u32,
            size: self.size as u64,
            first_key,
        }
    }

    fn sample(&mut self, config: &TableConfig, n: usize, beta: f64) -> RawSample {
        let capacity = config.capacity;
        let total = self.tree.total();
        let mut slots = Vec::with_capacity(n);
        for _ in 0..n {
            let mass = self.rng.random::<f64>() * total;
            // The tree is non-empty and every live leaf is positive.
            slots.push(self.tree.find(mass).unwrap_or(0));
        }
        let leaves: Vec<f64> = slots.iter().map(|s| self.tree.get(*s)).collect();
        let floor = match config.normalization {
            WeightNormalization::Table => self.tree.min(),
            WeightNormalization::Batch => leaves.iter().copied().reduce(f64::min),
        }
        .unwrap_or(1.0);
        // (N P_i)^-beta / max_j (N P_j)^-beta = (min_leaf / leaf_i)^beta.
        let weights = leaves
            .iter()
            .map(|l| ((floor / l).powf(beta)).min(1.0) as f32)
            .collect();
        // Store ids become pool indices: states first, then next states.
        let mut columns = self.items.gather(&slots);
        let mut distinct: Vec<(u32, Vec<u8>)> = Vec::new();
        let mut index_of = std::collections::HashMap::with_capacity(2 * n);
        for id in columns
            .observation_index
            .iter_mut()
            .chain(columns.next_observation_index.iter_mut())
        {
            let store_id = *id;
            *id = *index_of.entry(store_id).or_insert_with(|| {
                distinct.push((store_id, self.store.get(store_id).to_vec()));
                (distinct.len() - 1) as u32
            });
        }
        let (layout, num_actions) = self
            .spec
            .clone()
            .unwrap_or_else(|| (ObservationLayout::new("", 0, 0, 0, 0), 0));
        self.limiter.sampled(n as u64);
        RawSample {
            layout,
            num_actions,
            keys: slots.iter().map(|s| self.key_of(*s, capacity)).collect(),
            weights,
            columns,
            observations: distinct,
        }
    }

    fn update(
        &mut self,
        config: &TableConfig,
        keys: &[u64],
        priorities: &[f32],
    ) -> PrioritiesUpdated {
        let mut updated = 0;
        let mut ignored = 0;
        for (key, p) in keys.iter().zip(priorities) {
            match self.slot_of(*key, config.capacity) {
                Some(slot) => {
                    self.items.priorities[slot] = *p;
                    self.tree.set(slot, Self::leaf(config, *p));
                    updated += 1;
                }
                None => ignored += 1,
            }
        }
        self.priority_updates_total = self
            .priority_updates_total
            .saturating_add(u64::from(updated));
        self.ignored_updates_total = self
            .ignored_updates_total
            .saturating_add(u64::from(ignored));
        PrioritiesUpdated { updated, ignored }
    }

    fn image(&self) -> TableImage {
        let capacity = self.tree.capacity();
        let oldest = self.next_key - self.size as u64;
        let (inserts_total, samples_total) = self.limiter.counts();
        let mut image = TableImage {
            spec: self.spec.clone(),
            next_key: self.next_key,
            inserts_total,
            samples_total,
            priority_updates_total: self.priority_updates_total,
            ignored_updates_total: self.ignored_updates_total,
            items: Columns::with_capacity(self.size),
            ..TableImage::default()
        };
        let mut renumber = std::collections::HashMap::with_capacity(self.store.len());
        let mut number = |image: &mut TableImage, id: u32| -> u32 {
            *renumber.entry(id).or_insert_with(|| {
                image
                    .observation_offsets
                    .push(image.observation_data.len() as u64);
                image.observation_data.extend_from_slice(self.store.get(id));
                (image.observation_offsets.len() - 1) as u32
            })
        };
        for key in oldest..self.next_key {
            let slot = ((key - self.base_key) % capacity as u64) as usize;
            let Some(mut t) = self.items.get(slot) else {
                continue;
            };
            t.observation = number(&mut image, t.observation);
            t.next_observation = number(&mut image, t.next_observation);
            image.items.push(t);
        }
        image
    }
}
