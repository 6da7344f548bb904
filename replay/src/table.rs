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

use std::time::{Duration, Instant};

use crossroads_common::Shutdown;
use crossroads_config::{ReplayConfig, WeightNormalization};
use crossroads_types::ObservationEncoding;
use crossroads_types::batch::{
    BatchError, MAX_OBSERVATION_LEN, ObservationPool, ObservationSpec, RejectReason,
    TransitionBatch, check_priority,
};
use parking_lot::Mutex;
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use tokio::sync::Notify;

use crate::compact;
use crate::metrics::TableMetrics;
use crate::rate_limiter::{RateLimiter, RateLimiterConfig};
use crate::storage::{ObservationStore, content_hash};
use crate::sum_tree::SumTree;

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

/// A validated batch, encoded into the table's compact format before the
/// table's lock is taken.
#[derive(Debug, Clone)]
pub struct PreparedBatch {
    spec: ObservationSpec,
    num_actions: u32,
    actions: Vec<u32>,
    rewards: Vec<f32>,
    discounts: Vec<f32>,
    priorities: Vec<f32>,
    observation_index: Vec<u32>,
    next_observation_index: Vec<u32>,
    /// Per pool entry: content hash and range in `bytes`.
    entries: Vec<(u64, usize, usize)>,
    bytes: Vec<u8>,
}

impl PreparedBatch {
    /// Encodes a batch; validates it first (callers at a boundary already
    /// did, which makes this a cheap second pass).
    pub fn new(batch: TransitionBatch) -> Result<Self, BatchError> {
        batch.validate()?;
        let len = batch.spec.num_values().unwrap_or(0);
        let channels = compact::channels_of(&batch.spec.shape);
        let pool = &batch.observations;
        let mut bytes = Vec::new();
        let mut entries = Vec::with_capacity(pool.len());
        let (mut pairs, mut scratch) = (Vec::new(), Vec::new());
        for i in 0..pool.len() {
            let start = bytes.len();
            compact::from_wire(
                pool.encoding(),
                pool.get(i).unwrap_or_default(),
                len,
                channels,
                &mut pairs,
                &mut scratch,
                &mut bytes,
            );
            entries.push((content_hash(&bytes[start..]), start, bytes.len()));
        }
        Ok(Self {
            spec: batch.spec,
            num_actions: batch.num_actions,
            actions: batch.actions,
            rewards: batch.rewards,
            discounts: batch.discounts,
            priorities: batch.priorities,
            observation_index: batch.observation_index,
            next_observation_index: batch.next_observation_index,
            entries,
            bytes,
        })
    }

    /// Transitions in the batch.
    pub fn len(&self) -> usize {
        self.actions.len()
    }

    /// Whether it has none.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
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

/// A sampled batch with its keys and importance weights.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Item keys, batch order.
    pub keys: Vec<u64>,
    /// Importance weights, at most 1.
    pub weights: Vec<f32>,
    /// Priorities as stored.
    pub priorities: Vec<f32>,
    /// The items, observations sparse and each once.
    pub batch: TransitionBatch,
}

/// What a priority update did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Updated {
    /// Keys updated.
    pub updated: u32,
    /// Keys no longer in the table.
    pub ignored: u32,
}

/// A table's size, counters and limiter state.
#[derive(Debug, Clone, PartialEq)]
pub struct TableStats {
    /// Table name.
    pub name: String,
    /// Items held.
    pub size: u64,
    /// Items it can hold.
    pub capacity: u64,
    /// Items ever inserted (across restores).
    pub inserts_total: u64,
    /// Items ever sampled (across restores).
    pub samples_total: u64,
    /// Priorities updated.
    pub priority_updates_total: u64,
    /// Updates for keys no longer held.
    pub ignored_updates_total: u64,
    /// Limiter settings.
    pub limiter: RateLimiterConfig,
    /// Whether a sample may proceed now.
    pub can_sample: bool,
    /// Whether an insert may proceed now.
    pub can_insert: bool,
    /// Samples that had to wait (this process).
    pub sample_waits: u64,
    /// Inserts that had to wait (this process).
    pub insert_waits: u64,
    /// Bytes of memory the table holds.
    pub bytes: u64,
    /// Distinct observations held.
    pub observations: u64,
    /// Next key to be given.
    pub next_key: u64,
}

/// A table's whole content in FIFO order, for snapshots.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TableImage {
    /// Spec and action count the table holds, if it got a batch.
    pub spec: Option<(ObservationSpec, u32)>,
    /// Key the next insert gets; the items hold keys
    /// `next_key - len .. next_key`.
    pub next_key: u64,
    /// Items ever inserted.
    pub inserts_total: u64,
    /// Items ever sampled.
    pub samples_total: u64,
    /// Priority updates.
    pub priority_updates_total: u64,
    /// Ignored priority updates.
    pub ignored_updates_total: u64,
    /// Rate limiter's insert and sample counts.
    pub limiter_counts: (u64, u64),
    /// Columns, oldest first.
    pub actions: Vec<u32>,
    /// Rewards.
    pub rewards: Vec<f32>,
    /// Discounts.
    pub discounts: Vec<f32>,
    /// Raw priorities.
    pub priorities: Vec<f32>,
    /// Index into the observation list of each state.
    pub observation: Vec<u32>,
    /// Index into the observation list of each next state.
    pub next_observation: Vec<u32>,
    /// Start of each compact observation in `observation_data`.
    pub observation_offsets: Vec<u64>,
    /// Compact observations back to back.
    pub observation_data: Vec<u8>,
}

impl TableImage {
    /// Items in the image.
    pub fn len(&self) -> usize {
        self.actions.len()
    }

    /// Whether it holds no item.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }

    fn observation(&self, i: usize) -> Option<&[u8]> {
        let start = *self.observation_offsets.get(i)? as usize;
        let end = self
            .observation_offsets
            .get(i + 1)
            .map_or(self.observation_data.len(), |e| *e as usize);
        self.observation_data.get(start..end)
    }
}

#[derive(Debug)]
struct Inner {
    spec: Option<(ObservationSpec, u32)>,
    tree: SumTree,
    store: ObservationStore,
    actions: Vec<u32>,
    rewards: Vec<f32>,
    discounts: Vec<f32>,
    priorities: Vec<f32>,
    observation: Vec<u32>,
    next_observation: Vec<u32>,
    /// Key held by slot 0 of the ring's first lap.
    base_key: u64,
    next_key: u64,
    size: usize,
    rng: Xoshiro256PlusPlus,
    limiter: RateLimiter,
    inserts_total: u64,
    samples_total: u64,
    priority_updates_total: u64,
    ignored_updates_total: u64,
}

/// One prioritized table. Thread-safe (`&self` everywhere); share it in an
/// `Arc`.
#[derive(Debug)]
pub struct Table {
    config: TableConfig,
    inner: Mutex<Inner>,
    changed: Notify,
    metrics: TableMetrics,
}

impl Table {
    /// An empty table.
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

    /// Inserts a batch, waiting at most `timeout` for the rate limiter.
    /// All of the batch is stored or none of it.
    pub async fn insert(
        &self,
        batch: &PreparedBatch,
        timeout: Duration,
        shutdown: &Shutdown,
    ) -> Result<Inserted, TableError> {
        self.wait_for("insert", timeout, shutdown, |inner, config| {
            inner.check_spec(batch)?;
            if !inner.limiter.can_insert() {
                return Ok(None);
            }
            Ok(Some(inner.insert(config, batch)))
        })
        .await
    }

    /// Inserts a batch at once, whatever the rate limiter says (for the
    /// last batches drained at shutdown).
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
    /// exponent `beta`, waiting at most `timeout` for the rate limiter.
    pub async fn sample(
        &self,
        batch_size: usize,
        beta: f64,
        timeout: Duration,
        shutdown: &Shutdown,
    ) -> Result<Sample, TableError> {
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

    /// Sets new priorities. Every priority is checked first: one invalid
    /// value rejects the whole request and changes nothing. Keys no longer
    /// held are ignored and counted.
    pub fn update_priorities(
        &self,
        keys: &[u64],
        priorities: &[f32],
    ) -> Result<Updated, TableError> {
        if keys.len() != priorities.len() {
            return Err(BatchError::new(
                RejectReason::LengthMismatch,
                "priorities",
                format!("{} priorities for {} keys", priorities.len(), keys.len()),
            )
            .into());
        }
        for (i, p) in priorities.iter().enumerate() {
            check_priority(*p).map_err(|(reason, problem)| {
                BatchError::new(reason, format!("priorities[{i}]"), problem)
            })?;
        }
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
    pub fn stats(&self) -> TableStats {
        let inner = self.inner.lock();
        let (insert_waits, sample_waits) = inner.limiter.waits();
        TableStats {
            name: self.config.name.clone(),
            size: inner.size as u64,
            capacity: self.config.capacity as u64,
            inserts_total: inner.inserts_total,
            samples_total: inner.samples_total,
            priority_updates_total: inner.priority_updates_total,
            ignored_updates_total: inner.ignored_updates_total,
            limiter: self.config.limiter,
            can_sample: inner.limiter.can_sample() && inner.size > 0,
            can_insert: inner.limiter.can_insert(),
            sample_waits,
            insert_waits,
            bytes: inner.bytes() as u64,
            observations: inner.store.len() as u64,
            next_key: inner.next_key,
        }
    }

    /// A copy of the whole content, oldest item first.
    pub fn image(&self) -> TableImage {
        self.inner.lock().image()
    }

    /// Replaces the content by `image` (restoring a snapshot). When the
    /// image holds more items than the capacity, the oldest are dropped;
    /// returns how many.
    pub fn restore(&self, image: &TableImage) -> Result<usize, BatchError> {
        let n = image.len();
        let columns = [
            image.rewards.len(),
            image.discounts.len(),
            image.priorities.len(),
            image.observation.len(),
            image.next_observation.len(),
        ];
        if columns.iter().any(|c| *c != n) || image.next_key < n as u64 {
            return Err(BatchError::new(
                RejectReason::LengthMismatch,
                "items",
                "columns of different lengths",
            ));
        }
        let n_obs = image.observation_offsets.len();
        for (i, (o, no)) in image
            .observation
            .iter()
            .zip(&image.next_observation)
            .enumerate()
        {
            if *o as usize >= n_obs || *no as usize >= n_obs {
                return Err(BatchError::new(
                    RejectReason::IndexRange,
                    format!("items[{i}].observation"),
                    format!("refers to observation {} of {n_obs}", (*o).max(*no)),
                ));
            }
        }
        for (i, p) in image.priorities.iter().enumerate() {
            check_priority(*p).map_err(|(reason, problem)| {
                BatchError::new(reason, format!("items[{i}].priority"), problem)
            })?;
        }
        let keep = n.min(self.config.capacity);
        let skip = n - keep;
        let oldest = image.next_key - n as u64 + skip as u64;
        let mut fresh = Inner::new(&self.config, oldest);
        fresh.spec = image.spec.clone();
        fresh.next_key = oldest;
        let mut ids: Vec<Option<u32>> = vec![None; n_obs];
        for i in skip..n {
            let mut id_of = |fresh: &mut Inner, o: u32| -> Result<u32, BatchError> {
                match ids[o as usize] {
                    Some(id) => {
                        fresh.store.retain(id);
                        Ok(id)
                    }
                    None => {
                        let bytes = image.observation(o as usize).ok_or_else(|| {
                            BatchError::new(
                                RejectReason::ObservationEncoding,
                                format!("observations[{o}]"),
                                "out of the data",
                            )
                        })?;
                        let id = fresh.store.intern(bytes, content_hash(bytes));
                        ids[o as usize] = Some(id);
                        Ok(id)
                    }
                }
            };
            let o = id_of(&mut fresh, image.observation[i])?;
            let no = id_of(&mut fresh, image.next_observation[i])?;
            fresh.push_item(
                &self.config,
                image.actions[i],
                image.rewards[i],
                image.discounts[i],
                image.priorities[i],
                o,
                no,
            );
        }
        fresh.inserts_total = image.inserts_total;
        fresh.samples_total = image.samples_total;
        fresh.priority_updates_total = image.priority_updates_total;
        fresh.ignored_updates_total = image.ignored_updates_total;
        fresh
            .limiter
            .set_counts(image.limiter_counts.0, image.limiter_counts.1);
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
                            self.config.limiter.samples_per_insert,
                        ),
                    });
                }
                _ = shutdown.wait() => return Err(TableError::ShuttingDown),
            }
        }
    }
}

/// What a sample copied out under the lock; finished into a [`Sample`]
/// without it.
struct RawSample {
    spec: ObservationSpec,
    num_actions: u32,
    keys: Vec<u64>,
    weights: Vec<f32>,
    priorities: Vec<f32>,
    actions: Vec<u32>,
    rewards: Vec<f32>,
    discounts: Vec<f32>,
    observation_index: Vec<u32>,
    next_observation_index: Vec<u32>,
    /// Store id and compact bytes of each distinct observation.
    observations: Vec<(u32, Vec<u8>)>,
}

impl RawSample {
    fn finish(self) -> Result<Sample, TableError> {
        let len = self.spec.num_values().unwrap_or(MAX_OBSERVATION_LEN);
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
            priorities: self.priorities.clone(),
            batch: TransitionBatch {
                spec: self.spec,
                num_actions: self.num_actions,
                actions: self.actions,
                rewards: self.rewards,
                discounts: self.discounts,
                priorities: self.priorities,
                observations: pool,
                observation_index: self.observation_index,
                next_observation_index: self.next_observation_index,
            },
        })
    }
}

impl Inner {
    fn new(config: &TableConfig, base_key: u64) -> Self {
        Self {
            spec: None,
            tree: SumTree::new(config.capacity),
            store: ObservationStore::new(),
            actions: Vec::new(),
            rewards: Vec::new(),
            discounts: Vec::new(),
            priorities: Vec::new(),
            observation: Vec::new(),
            next_observation: Vec::new(),
            base_key,
            next_key: base_key,
            size: 0,
            rng: Xoshiro256PlusPlus::seed_from_u64(config.seed),
            limiter: RateLimiter::new(config.limiter),
            inserts_total: 0,
            samples_total: 0,
            priority_updates_total: 0,
            ignored_updates_total: 0,
        }
    }

    fn bytes(&self) -> usize {
        self.tree.bytes()
            + self.store.bytes()
            + 4 * (self.actions.capacity()
                + self.rewards.capacity()
                + self.discounts.capacity()
                + self.priorities.capacity()
                + self.observation.capacity()
                + self.next_observation.capacity())
    }

    fn check_spec(&self, batch: &PreparedBatch) -> Result<(), BatchError> {
        match &self.spec {
            Some((spec, actions)) if *spec != batch.spec || *actions != batch.num_actions => {
                Err(BatchError::new(
                    RejectReason::Spec,
                    "spec",
                    format!(
                        "the table holds {spec} with {actions} actions; the batch is {} with {} actions",
                        batch.spec, batch.num_actions
                    ),
                ))
            }
            _ => Ok(()),
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

    /// Appends one item, evicting the oldest when full.
    #[allow(clippy::too_many_arguments)]
    fn push_item(
        &mut self,
        config: &TableConfig,
        action: u32,
        reward: f32,
        discount: f32,
        priority: f32,
        observation: u32,
        next_observation: u32,
    ) {
        let capacity = config.capacity;
        let slot = ((self.next_key - self.base_key) % capacity as u64) as usize;
        if slot < self.actions.len() {
            if self.size == capacity {
                self.store.release(self.observation[slot]);
                self.store.release(self.next_observation[slot]);
                self.size -= 1;
            }
            self.actions[slot] = action;
            self.rewards[slot] = reward;
            self.discounts[slot] = discount;
            self.priorities[slot] = priority;
            self.observation[slot] = observation;
            self.next_observation[slot] = next_observation;
        } else {
            self.actions.push(action);
            self.rewards.push(reward);
            self.discounts.push(discount);
            self.priorities.push(priority);
            self.observation.push(observation);
            self.next_observation.push(next_observation);
        }
        self.tree.set(slot, Self::leaf(config, priority));
        self.size += 1;
        self.next_key += 1;
    }

    fn insert(&mut self, config: &TableConfig, batch: &PreparedBatch) -> Inserted {
        if self.spec.is_none() {
            self.spec = Some((batch.spec.clone(), batch.num_actions));
        }
        let first_key = self.next_key;
        let mut ids: Vec<Option<u32>> = vec![None; batch.entries.len()];
        for i in 0..batch.len() {
            let mut id_of = |store: &mut ObservationStore, pool_index: u32| {
                let p = pool_index as usize;
                match ids[p] {
                    Some(id) => {
                        store.retain(id);
                        id
                    }
                    None => {
                        let (hash, start, end) = batch.entries[p];
                        let id = store.intern(&batch.bytes[start..end], hash);
                        ids[p] = Some(id);
                        id
                    }
                }
            };
            let o = id_of(&mut self.store, batch.observation_index[i]);
            let no = id_of(&mut self.store, batch.next_observation_index[i]);
            self.push_item(
                config,
                batch.actions[i],
                batch.rewards[i],
                batch.discounts[i],
                batch.priorities[i],
                o,
                no,
            );
        }
        let n = batch.len() as u64;
        self.limiter.inserted(n);
        self.inserts_total += n;
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
        let mut distinct: Vec<(u32, Vec<u8>)> = Vec::new();
        let mut index_of = std::collections::HashMap::with_capacity(2 * n);
        let mut pool_index = |store: &ObservationStore, id: u32| -> u32 {
            *index_of.entry(id).or_insert_with(|| {
                distinct.push((id, store.get(id).to_vec()));
                (distinct.len() - 1) as u32
            })
        };
        let observation_index = slots
            .iter()
            .map(|s| pool_index(&self.store, self.observation[*s]))
            .collect();
        let next_observation_index = slots
            .iter()
            .map(|s| pool_index(&self.store, self.next_observation[*s]))
            .collect();
        let (spec, num_actions) = self
            .spec
            .clone()
            .unwrap_or_else(|| (ObservationSpec::new("", Vec::new()), 0));
        self.limiter.sampled(n as u64);
        self.samples_total += n as u64;
        RawSample {
            spec,
            num_actions,
            keys: slots.iter().map(|s| self.key_of(*s, capacity)).collect(),
            weights,
            priorities: slots.iter().map(|s| self.priorities[*s]).collect(),
            actions: slots.iter().map(|s| self.actions[*s]).collect(),
            rewards: slots.iter().map(|s| self.rewards[*s]).collect(),
            discounts: slots.iter().map(|s| self.discounts[*s]).collect(),
            observation_index,
            next_observation_index,
            observations: distinct,
        }
    }

    fn update(&mut self, config: &TableConfig, keys: &[u64], priorities: &[f32]) -> Updated {
        let mut updated = 0;
        let mut ignored = 0;
        for (key, p) in keys.iter().zip(priorities) {
            match self.slot_of(*key, config.capacity) {
                Some(slot) => {
                    self.priorities[slot] = *p;
                    self.tree.set(slot, Self::leaf(config, *p));
                    updated += 1;
                }
                None => ignored += 1,
            }
        }
        self.priority_updates_total += u64::from(updated);
        self.ignored_updates_total += u64::from(ignored);
        Updated { updated, ignored }
    }

    fn image(&self) -> TableImage {
        let capacity = self.tree.capacity();
        let oldest = self.next_key - self.size as u64;
        let mut image = TableImage {
            spec: self.spec.clone(),
            next_key: self.next_key,
            inserts_total: self.inserts_total,
            samples_total: self.samples_total,
            priority_updates_total: self.priority_updates_total,
            ignored_updates_total: self.ignored_updates_total,
            limiter_counts: self.limiter.counts(),
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
            image.actions.push(self.actions[slot]);
            image.rewards.push(self.rewards[slot]);
            image.discounts.push(self.discounts[slot]);
            image.priorities.push(self.priorities[slot]);
            let o = number(&mut image, self.observation[slot]);
            let no = number(&mut image, self.next_observation[slot]);
            image.observation.push(o);
            image.next_observation.push(no);
        }
        image
    }
}
