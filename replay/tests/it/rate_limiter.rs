//! The rate limiter through the table: minimum size, samples per insert,
//! timeouts, callers that go away mid-wait, shutdown.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crossroads_common::Shutdown;
use crossroads_replay::rate_limiter::RateLimiterConfig;
use crossroads_replay::{Table, TableError, TableMetrics};

use crate::util::{WAIT, prepared, table_config, wait_until};

fn limited(min: u64, ratio: f64, tolerance: f64) -> Arc<Table> {
    let mut c = table_config(1000, 1.0);
    c.limiter = RateLimiterConfig {
        min_size_to_sample: min,
        samples_per_insert: ratio,
        tolerance,
        ramp: None,
    };
    Arc::new(Table::new(c, TableMetrics::unregistered("t")))
}

#[tokio::test]
async fn sampling_waits_for_the_minimum_size_then_proceeds() {
    let t = limited(10, 0.0, 0.0);
    let shutdown = Shutdown::new();
    t.insert(&prepared(0, 5, None), Duration::from_secs(1), &shutdown)
        .await
        .expect("insert");
    let sampler = {
        let t = t.clone();
        let shutdown = shutdown.clone();
        tokio::spawn(async move { t.sample(4, 0.0, Duration::from_secs(10), &shutdown).await })
    };
    wait_until(
        WAIT,
        "the sample to wait for the minimum size",
        async || t.stats().limiter.sample_waits_total == 1,
    )
    .await;
    assert!(!sampler.is_finished(), "5 of 10 inserted: the sample waits");
    assert!(!t.stats().limiter.can_sample);
    t.insert(&prepared(5, 5, None), Duration::from_secs(1), &shutdown)
        .await
        .expect("insert");
    let s = tokio::time::timeout(Duration::from_secs(5), sampler)
        .await
        .expect("woken by the insert")
        .expect("task")
        .expect("sample");
    assert_eq!(s.keys.len(), 4);
    assert_eq!(t.stats().limiter.sample_waits_total, 1);
}

#[tokio::test]
async fn a_sample_that_cannot_proceed_times_out() {
    let t = limited(3, 0.0, 0.0);
    let start = Instant::now();
    let err = t
        .sample(1, 0.0, Duration::from_millis(200), &Shutdown::new())
        .await
        .expect_err("empty table");
    let waited = start.elapsed();
    assert!(
        matches!(err, TableError::Timeout { op: "sample", .. }),
        "{err:?}"
    );
    assert!(
        waited >= Duration::from_millis(200) && waited < Duration::from_secs(3),
        "{waited:?}"
    );
    assert!(err.to_string().contains("min size 3"), "{err}");
}

#[tokio::test]
async fn inserts_wait_for_samples_under_a_ratio() {
    // Two samples per insert, tolerance 8, from 4 items: the gap
    // inserts * 2 - samples stays within 8 +- 8.
    let t = limited(4, 2.0, 8.0);
    let shutdown = Shutdown::new();
    let fast = Duration::from_millis(150);
    t.insert(&prepared(0, 4, None), fast, &shutdown)
        .await
        .expect("below the minimum");
    // gap 8: inserts allowed while gap + 2 <= 16.
    for i in 0..4 {
        t.insert(&prepared(10 + i, 1, None), fast, &shutdown)
            .await
            .expect("within tolerance");
    }
    // gap 16: the next insert must wait for samples.
    let err = t
        .insert(&prepared(20, 1, None), fast, &shutdown)
        .await
        .expect_err("too far ahead");
    assert!(
        matches!(err, TableError::Timeout { op: "insert", .. }),
        "{err:?}"
    );
    assert_eq!(t.stats().info.size, 8, "the refused batch was not stored");
    let inserter = {
        let t = t.clone();
        let shutdown = shutdown.clone();
        tokio::spawn(async move {
            t.insert(&prepared(20, 1, None), Duration::from_secs(10), &shutdown)
                .await
        })
    };
    // The refused insert above waited once; this one is the second.
    wait_until(WAIT, "the insert to wait for samples", async || {
        t.stats().limiter.insert_waits_total == 2
    })
    .await;
    assert!(!inserter.is_finished());
    t.sample(4, 0.0, Duration::from_secs(1), &shutdown)
        .await
        .expect("sample");
    tokio::time::timeout(Duration::from_secs(5), inserter)
        .await
        .expect("woken by the sample")
        .expect("task")
        .expect("insert");
    // Samples are limited too: from gap 14 down to the lower bound 0.
    t.sample(14, 0.0, Duration::from_secs(1), &shutdown)
        .await
        .expect("within tolerance");
    let err = t
        .sample(1, 0.0, fast, &shutdown)
        .await
        .expect_err("too far ahead");
    assert!(
        matches!(err, TableError::Timeout { op: "sample", .. }),
        "{err:?}"
    );
    let stats = t.stats();
    assert!(
        stats.limiter.insert_waits_total >= 2 && stats.limiter.sample_waits_total >= 1,
        "{stats:?}"
    );
}

#[tokio::test]
async fn items_reserved_and_not_yet_stored_hold_back_inserts_until_given_up() {
    // Two samples per insert within 2 samples either way, from 4 items:
    // once 4 are in, at most 5 without a sample.
    let t = limited(4, 2.0, 2.0);
    let shutdown = Shutdown::new();
    let five = prepared(0, 5, None);
    let reserved = t
        .reserve(&five, WAIT, &shutdown)
        .await
        .expect("below the minimum size");
    // Five items on their way to the log count as inserted: a sixth waits.
    let waited = t
        .insert(&prepared(5, 1, None), Duration::from_millis(50), &shutdown)
        .await;
    assert!(
        matches!(waited, Err(TableError::Timeout { .. })),
        "{waited:?}"
    );
    // Given up (their log write failed), they hold nothing back.
    drop(reserved);
    t.insert(&prepared(5, 1, None), Duration::from_secs(1), &shutdown)
        .await
        .expect("room again");
    assert_eq!(t.stats().info.inserts_total, 1);
}

#[tokio::test]
async fn a_caller_that_goes_away_mid_wait_leaves_the_table_usable() {
    let t = limited(2, 0.0, 0.0);
    let shutdown = Shutdown::new();
    let waiter = {
        let t = t.clone();
        let shutdown = shutdown.clone();
        tokio::spawn(async move { t.sample(1, 0.0, Duration::from_secs(3600), &shutdown).await })
    };
    wait_until(WAIT, "the sample to wait", async || {
        t.stats().limiter.sample_waits_total == 1
    })
    .await;
    waiter.abort();
    assert!(waiter.await.expect_err("aborted").is_cancelled());
    t.insert(&prepared(0, 2, None), Duration::from_secs(1), &shutdown)
        .await
        .expect("insert");
    let s = tokio::time::timeout(
        Duration::from_secs(5),
        t.sample(2, 0.0, Duration::from_secs(1), &shutdown),
    )
    .await
    .expect("not wedged")
    .expect("sample");
    assert_eq!(s.keys.len(), 2);
}

#[tokio::test]
async fn shutdown_ends_a_wait() {
    let t = limited(5, 0.0, 0.0);
    let shutdown = Shutdown::new();
    let waiter = {
        let t = t.clone();
        let shutdown = shutdown.clone();
        tokio::spawn(async move { t.sample(1, 0.0, Duration::from_secs(3600), &shutdown).await })
    };
    wait_until(WAIT, "the sample to wait", async || {
        t.stats().limiter.sample_waits_total == 1
    })
    .await;
    shutdown.trigger();
    let r = tokio::time::timeout(Duration::from_secs(5), waiter)
        .await
        .expect("ended")
        .expect("task");
    assert_eq!(r.expect_err("shutting down"), TableError::ShuttingDown);
}
