//! Shared helpers: small tables, batches and configs.

use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_config::Config;
use crossroads_config::WeightNormalization;
use crossroads_replay::rate_limiter::RateLimiterConfig;
use crossroads_replay::{PreparedBatch, Table, TableConfig, TableMetrics};
use crossroads_types::{
    ObservationEncoding, ObservationLayout, Transition, TransitionBatch, ValidBatch,
};

pub const SPEC_LEN: usize = 2 * 3 * 2;

pub fn layout() -> ObservationLayout {
    ObservationLayout::new("toy", 2, 3, 2, 0)
}

pub fn table_config(capacity: usize, alpha: f64) -> TableConfig {
    TableConfig {
        name: "t".to_owned(),
        capacity,
        alpha,
        min_priority: 1e-6,
        normalization: WeightNormalization::Table,
        seed: 42,
        limiter: RateLimiterConfig {
            min_size_to_sample: 1,
            samples_per_insert: 0.0,
            tolerance: 0.0,
            ramp: None,
        },
    }
}

pub fn table(capacity: usize, alpha: f64) -> Table {
    Table::new(
        table_config(capacity, alpha),
        TableMetrics::unregistered("t"),
    )
}

/// An observation that encodes `tag` in its values, so tests can tell
/// items apart after a round trip.
pub fn obs(tag: u32) -> Vec<f32> {
    let mut v = vec![0.0; SPEC_LEN];
    v[(tag as usize) % SPEC_LEN] = tag as f32 + 1.0;
    v[SPEC_LEN - 1] = 0.5;
    v
}

/// `n` transitions tagged `first..first + n`: reward = tag, action =
/// tag % 4, priorities as given (or 1), next state shared with the next
/// transition's state.
pub fn batch(first: u32, n: u32, priorities: Option<&[f32]>) -> TransitionBatch {
    let mut b = TransitionBatch::new(layout(), 4, ObservationEncoding::SparseF32);
    let mut current = b.push_observation(&obs(first));
    for i in 0..n {
        let tag = first + i;
        let next = b.push_observation(&obs(tag + 1));
        b.push(Transition {
            observation: current,
            action: tag % 4,
            reward: tag as f32,
            discount: 0.9,
            priority: priorities.map_or(1.0, |p| p[i as usize]),
            next_observation: next,
        });
        current = next;
    }
    b
}

/// [`batch`], validated.
pub fn valid(first: u32, n: u32, priorities: Option<&[f32]>) -> ValidBatch {
    ValidBatch::new(batch(first, n, priorities)).expect("valid batch")
}

pub fn prepared(first: u32, n: u32, priorities: Option<&[f32]>) -> PreparedBatch {
    PreparedBatch::new(valid(first, n, priorities))
}

pub async fn insert(t: &Table, first: u32, n: u32, priorities: Option<&[f32]>) {
    t.insert(
        &prepared(first, n, priorities),
        Duration::from_secs(5),
        &Shutdown::new(),
    )
    .await
    .expect("insert");
}

/// A config for a server on port 0, no shared memory, no periodic
/// snapshots, table "t".
pub fn server_config(snapshot_dir: Option<&std::path::Path>) -> Config {
    let mut c = Config::default();
    c.replay.listen = "127.0.0.1:0".parse().expect("addr");
    c.replay.table = "t".to_owned();
    c.replay.capacity = 1000;
    c.replay.min_size_to_sample = 1;
    c.replay.shm_ingest = false;
    c.replay.snapshot_dir = snapshot_dir.map(|d| d.to_path_buf());
    c.replay.snapshot_interval_secs = 0;
    c.replay.max_message_bytes = 1 << 20;
    c.replay.max_batch_transitions = 256;
    c.replay.max_sample_batch = 512;
    c
}

/// How long a test waits for something that takes milliseconds, before it
/// fails: generous, since tests share the cores with each other.
pub const WAIT: Duration = Duration::from_secs(10);

/// Waits until `condition` holds, checking every 5 ms; fails naming `what`
/// once `timeout` has passed without it.
pub async fn wait_until(timeout: Duration, what: &str, mut condition: impl AsyncFnMut() -> bool) {
    let deadline = tokio::time::Instant::now() + timeout;
    while !condition().await {
        assert!(
            tokio::time::Instant::now() < deadline,
            "waited {timeout:?} for {what}, in vain"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// A shared-memory prefix no other test or process uses.
pub fn unique_prefix(test: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!("crossroads-test/{test}/{}-{nanos}", std::process::id())
}
