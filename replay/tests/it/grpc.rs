//! The gRPC service on port 0 through the common client: round trip,
//! every bad input rejected with the table untouched, clean restarts,
//! callers that go away, metrics.

use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_config::Config;
use crossroads_config::TransportConfig;
use crossroads_replay::{RunningServer, TableImage};
use crossroads_transport::grpc::{ClientError, ReplayClient};
use crossroads_types::{RejectReason, TransitionBatch};

use crate::util::{WAIT, batch, server_config, wait_until};

async fn serve(config: &Config) -> (RunningServer, Shutdown, prometheus::Registry) {
    let registry = crossroads_common::metrics::registry("replay").expect("registry");
    let shutdown = Shutdown::new();
    let server = crossroads_replay::start(config, Some(&registry), shutdown.clone())
        .await
        .expect("start");
    (server, shutdown, registry)
}

fn client(server: &RunningServer, table: &str) -> ReplayClient {
    let transport = TransportConfig {
        replay_endpoint: format!("http://{}", server.local_addr()),
        request_timeout_ms: 5_000,
        ..TransportConfig::default()
    };
    ReplayClient::new(&transport, table).expect("client")
}

async fn stop(server: RunningServer, shutdown: Shutdown) {
    shutdown.trigger();
    tokio::time::timeout(Duration::from_secs(15), server.join())
        .await
        .expect("stops")
        .expect("clean stop");
}

fn image(server: &RunningServer) -> TableImage {
    server.table("t").expect("table").image()
}

#[tokio::test]
async fn insert_sample_update_info_round_trip_on_port_0() {
    let (server, shutdown, registry) = serve(&server_config(None)).await;
    assert_ne!(server.local_addr().port(), 0);
    let c = client(&server, "t");

    let mut stream = c.insert_stream(4).await.expect("stream");
    for b in 0..3 {
        stream.send(batch(b * 10, 10, None)).await.expect("send");
    }
    let acks = stream.finish().await.expect("acks");
    assert_eq!(
        acks.iter().map(|a| a.batch_id).collect::<Vec<_>>(),
        vec![0, 1, 2]
    );
    assert_eq!(acks.iter().map(|a| a.inserted).sum::<u32>(), 30);
    assert_eq!(acks[2].table_size, 30);
    let ack = c.insert(batch(30, 5, None)).await.expect("one batch");
    assert_eq!((ack.inserted, ack.table_size), (5, 35));

    let s = c
        .sample(16, 0.4, Duration::from_secs(1))
        .await
        .expect("sample");
    assert_eq!((s.keys.len(), s.weights.len(), s.batch.len()), (16, 16, 16));
    assert!(s.weights.iter().all(|w| *w > 0.0 && *w <= 1.0));
    for (k, r) in s.keys.iter().zip(&s.batch.columns.rewards) {
        assert_eq!(*k as f32, *r, "key names the item");
    }
    let u = c
        .update_priorities(s.keys.clone(), vec![2.0; 16])
        .await
        .expect("update");
    assert_eq!((u.updated, u.ignored), (16, 0));

    let info = c.info().await.expect("info");
    assert_eq!(
        (info.name.as_str(), info.size, info.capacity),
        ("t", 35, 1000)
    );
    assert_eq!(
        (
            info.inserts_total,
            info.samples_total,
            info.priority_updates_total
        ),
        (35, 16, 16)
    );
    let rl = info.rate_limiter.expect("limiter");
    assert!(rl.can_sample && rl.can_insert);
    assert!(info.bytes_stored > 0);

    let err = c.snapshot().await.expect_err("no snapshot dir");
    assert_eq!(err.code(), Some(tonic::Code::FailedPrecondition));

    let text = crossroads_common::metrics::render(&registry);
    for name in [
        "crossroads_replay_size_items{table=\"t\"} 35",
        "crossroads_replay_capacity_items{table=\"t\"} 1000",
        "crossroads_replay_inserts_total{table=\"t\",transport=\"grpc\"} 35",
        "crossroads_replay_samples_total{table=\"t\"} 16",
        "crossroads_replay_priority_updates_total{table=\"t\"} 16",
        "crossroads_replay_storage_bytes{table=\"t\"}",
        "crossroads_replay_rejections_total{reason=\"non_finite_reward\"} 0",
        "crossroads_replay_snapshot_age_seconds -1",
    ] {
        assert!(text.contains(name), "{name} missing from\n{text}");
    }
    stop(server, shutdown).await;
}

type Mutation = fn(&mut TransitionBatch);

#[tokio::test]
async fn every_bad_input_is_rejected_naming_the_field_and_changes_nothing() {
    let (server, shutdown, _registry) = serve(&server_config(None)).await;
    let c = client(&server, "t");
    c.insert(batch(0, 8, None)).await.expect("seed the table");
    let before = image(&server);

    let cases: Vec<(&str, Mutation, tonic::Code, &str, RejectReason)> = vec![
        (
            "observation layout not the table's",
            |b| b.layout.cols = 3,
            tonic::Code::InvalidArgument,
            "layout",
            RejectReason::Spec,
        ),
        (
            "wrong observation length",
            |b| {
                let (enc, offsets, mut data) = b.observations.clone().into_parts();
                data.truncate(data.len() - 3);
                b.observations = crossroads_types::ObservationPool::from_parts(enc, offsets, data);
            },
            tonic::Code::InvalidArgument,
            "batch.observations[",
            RejectReason::ObservationLength,
        ),
        (
            "NaN reward",
            |b| b.columns.rewards[2] = f32::NAN,
            tonic::Code::InvalidArgument,
            "batch.rewards[2]",
            RejectReason::NonFiniteReward,
        ),
        (
            "infinite reward",
            |b| b.columns.rewards[0] = f32::NEG_INFINITY,
            tonic::Code::InvalidArgument,
            "batch.rewards[0]",
            RejectReason::NonFiniteReward,
        ),
        (
            "infinite priority",
            |b| b.columns.priorities[1] = f32::INFINITY,
            tonic::Code::InvalidArgument,
            "batch.priorities[1]",
            RejectReason::NonFinitePriority,
        ),
        (
            "negative priority",
            |b| b.columns.priorities[3] = -0.5,
            tonic::Code::InvalidArgument,
            "batch.priorities[3]",
            RejectReason::NegativePriority,
        ),
        (
            "NaN observation value",
            |b| {
                let mut fresh = TransitionBatch::new(
                    b.layout.clone(),
                    4,
                    crossroads_types::ObservationEncoding::DenseF32,
                );
                let mut v = vec![0.0; crate::util::SPEC_LEN];
                v[4] = f32::NAN;
                let o = fresh.push_observation(&v);
                for i in 0..b.len() {
                    let mut t = b.transition(i).expect("in range");
                    t.observation = o;
                    t.next_observation = o;
                    fresh.push(t);
                }
                *b = fresh;
            },
            tonic::Code::InvalidArgument,
            "batch.observations[0]",
            RejectReason::NonFiniteObservation,
        ),
        (
            "action out of range",
            |b| b.columns.actions[1] = 4,
            tonic::Code::InvalidArgument,
            "batch.actions[1]",
            RejectReason::ActionRange,
        ),
        (
            "discount above 1",
            |b| b.columns.discounts[0] = 1.5,
            tonic::Code::InvalidArgument,
            "batch.discounts[0]",
            RejectReason::Discount,
        ),
        (
            "observation index out of the pool",
            |b| b.columns.next_observation_index[0] = 99,
            tonic::Code::InvalidArgument,
            "batch.next_observation_index[0]",
            RejectReason::IndexRange,
        ),
        (
            "columns of different lengths",
            |b| {
                b.columns.rewards.pop();
            },
            tonic::Code::InvalidArgument,
            "batch.rewards",
            RejectReason::LengthMismatch,
        ),
        (
            "too many transitions",
            |b| *b = batch(0, 300, None),
            tonic::Code::ResourceExhausted,
            "batch.actions",
            RejectReason::Oversized,
        ),
        (
            "message above the size limit",
            |b| {
                let v: Vec<f32> = (0..crate::util::SPEC_LEN).map(|i| i as f32 + 1.0).collect();
                let mut big = TransitionBatch::new(
                    b.layout.clone(),
                    4,
                    crossroads_types::ObservationEncoding::DenseF32,
                );
                for _ in 0..30_000 {
                    big.push_observation(&v);
                }
                big.push(b.transition(0).expect("one"));
                *b = big;
            },
            tonic::Code::ResourceExhausted,
            "too large",
            RejectReason::Oversized,
        ),
    ];
    for (what, mutate, code, field, reason) in cases {
        let mut b = batch(100, 8, None);
        mutate(&mut b);
        let err = c.insert(b).await.expect_err(what);
        let ClientError::Status { code: got, message } = &err else {
            panic!("{what}: {err:?}");
        };
        assert_eq!(*got, code, "{what}: {message}");
        assert!(
            message.contains(field),
            "{what}: {message:?} should name {field}"
        );
        let info = c.info().await.expect("info");
        assert!(
            info.rejections_total
                .get(reason.as_str())
                .copied()
                .unwrap_or(0)
                >= 1,
            "{what}: counter {reason} in {:?}",
            info.rejections_total
        );
        assert_eq!(image(&server), before, "{what}: table changed");
    }

    // Unknown table, on every call.
    let other = client(&server, "nope");
    let err = other
        .insert(batch(0, 2, None))
        .await
        .expect_err("unknown table");
    assert_eq!(err.code(), Some(tonic::Code::InvalidArgument));
    assert!(err.to_string().contains("table"), "{err}");
    for err in [
        other
            .sample(1, 0.0, Duration::from_millis(10))
            .await
            .expect_err("sample"),
        other
            .update_priorities(vec![0], vec![1.0])
            .await
            .expect_err("update"),
        other.info().await.expect_err("info"),
    ] {
        assert_eq!(err.code(), Some(tonic::Code::InvalidArgument), "{err}");
        assert!(err.to_string().contains("nope"), "{err}");
    }

    // Bad priority updates and sample requests.
    for (keys, priorities, field) in [
        (vec![0, 1], vec![1.0, f32::NAN], "priorities[1]"),
        (vec![0], vec![-2.0], "priorities[0]"),
        (vec![0, 1], vec![1.0], "priorities"),
    ] {
        let err = c
            .update_priorities(keys, priorities)
            .await
            .expect_err(field);
        assert_eq!(err.code(), Some(tonic::Code::InvalidArgument), "{err}");
        assert!(err.to_string().contains(field), "{err}");
    }
    let err = c
        .update_priorities(vec![0; 600], vec![1.0; 600])
        .await
        .expect_err("too many");
    assert_eq!(err.code(), Some(tonic::Code::ResourceExhausted), "{err}");
    for (size, beta, code, field) in [
        (0, 0.5, tonic::Code::InvalidArgument, "batch_size"),
        (4, 1.5, tonic::Code::InvalidArgument, "beta"),
        (4, f32::NAN, tonic::Code::InvalidArgument, "beta"),
        (10_000, 0.5, tonic::Code::ResourceExhausted, "batch_size"),
    ] {
        let err = c
            .sample(size, beta, Duration::from_millis(10))
            .await
            .expect_err(field);
        assert_eq!(err.code(), Some(code), "{err}");
        assert!(err.to_string().contains(field), "{err}");
    }
    let info = c.info().await.expect("info");
    assert_eq!(
        info.samples_total, 0,
        "no bad sample request counted as a sample"
    );
    assert_eq!(info.priority_updates_total, 0);
    assert_eq!(image(&server), before);
    stop(server, shutdown).await;
}

#[tokio::test]
async fn acknowledged_transitions_survive_a_clean_restart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = server_config(Some(dir.path()));
    let (server, shutdown, _r) = serve(&config).await;
    let c = client(&server, "t");
    let mut stream = c.insert_stream(8).await.expect("stream");
    for b in 0..5 {
        stream.send(batch(b * 20, 20, None)).await.expect("send");
    }
    let acked: u32 = stream
        .finish()
        .await
        .expect("acks")
        .iter()
        .map(|a| a.inserted)
        .sum();
    assert_eq!(acked, 100);
    let s = c
        .sample(10, 0.5, Duration::from_secs(1))
        .await
        .expect("sample");
    c.update_priorities(s.keys, vec![3.0; 10])
        .await
        .expect("update");
    let before = image(&server);
    stop(server, shutdown).await;

    let (server, shutdown, _r) = serve(&config).await;
    assert_eq!(image(&server), before, "everything acknowledged came back");
    let info = client(&server, "t").info().await.expect("info");
    assert_eq!(
        (info.size, info.inserts_total, info.samples_total),
        (100, 100, 10)
    );
    assert!(info.last_snapshot_unix_ms > 0);
    let written = client(&server, "t").snapshot().await.expect("snapshot now");
    assert_eq!(written.items, 100);
    assert!(written.path.starts_with(&dir.path().display().to_string()));
    stop(server, shutdown).await;
}

#[tokio::test]
async fn callers_that_go_away_do_not_wedge_the_server() {
    let mut config = server_config(None);
    config.replay.min_size_to_sample = 50;
    let (server, shutdown, _r) = serve(&config).await;
    let c = client(&server, "t");
    // A learner that gives up on a long sample (its future dropped).
    let gave_up = tokio::time::timeout(
        Duration::from_millis(200),
        c.sample(4, 0.0, Duration::from_secs(60)),
    )
    .await;
    assert!(gave_up.is_err(), "the sample was still waiting");
    // An actor that drops its stream once its batch is stored, its ack
    // unread: the server answers nobody.
    let table = server.table("t").expect("table");
    let mut stream = c.insert_stream(2).await.expect("stream");
    stream.send(batch(0, 10, None)).await.expect("send");
    wait_until(WAIT, "the streamed batch to be stored", async || {
        table.stats().info.size == 10
    })
    .await;
    drop(stream);
    // One that drops its stream with a batch still on the way: whenever
    // the server gets to it, the batch is all in or all out.
    let mut stream = c.insert_stream(2).await.expect("stream");
    stream.send(batch(10, 10, None)).await.expect("send");
    drop(stream);
    // Everyone else carries on.
    c.insert(batch(20, 40, None)).await.expect("insert");
    let size = c.info().await.expect("info").size;
    assert!(
        size == 50 || size == 60,
        "the dropped batch is all in or all out: {size}"
    );
    c.insert(batch(60, 10, None)).await.expect("insert");
    let s = tokio::time::timeout(
        Duration::from_secs(5),
        c.sample(4, 0.0, Duration::from_secs(1)),
    )
    .await
    .expect("answers")
    .expect("sample");
    assert_eq!(s.keys.len(), 4);
    stop(server, shutdown).await;
}

#[tokio::test]
async fn shutdown_ends_open_streams_and_waiting_samples() {
    let mut config = server_config(None);
    config.replay.min_size_to_sample = 1000;
    let (server, shutdown, _r) = serve(&config).await;
    let c = client(&server, "t");
    let mut stream = c.insert_stream(2).await.expect("stream");
    stream.send(batch(0, 5, None)).await.expect("send");
    stream.next_ack().await.expect("ack");
    let waiting = tokio::spawn({
        let c = c.clone();
        async move { c.sample(1, 0.0, Duration::from_secs(60)).await }
    });
    let table = server.table("t").expect("table");
    wait_until(
        WAIT,
        "the sample to wait for the minimum size",
        async || table.stats().limiter.sample_waits_total == 1,
    )
    .await;
    stop(server, shutdown).await;
    let err = waiting.await.expect("task").expect_err("server gone");
    assert!(err.is_retryable(), "{err:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn many_actors_stream_while_the_learner_samples_and_updates() {
    let mut config = server_config(None);
    config.replay.capacity = 300;
    config.replay.min_size_to_sample = 64;
    let (server, shutdown, _r) = serve(&config).await;
    let mut actors = Vec::new();
    for a in 0..4u32 {
        let c = client(&server, "t");
        actors.push(tokio::spawn(async move {
            let mut stream = c.insert_stream(4).await.expect("stream");
            let mut acked = 0;
            for b in 0..40u32 {
                if stream.is_full() {
                    acked += stream.next_ack().await.expect("ack").inserted;
                }
                stream
                    .send(batch(a * 100_000 + b * 8, 8, None))
                    .await
                    .expect("send");
            }
            for ack in stream.finish().await.expect("acks") {
                acked += ack.inserted;
            }
            acked
        }));
    }
    let learner = {
        let c = client(&server, "t");
        tokio::spawn(async move {
            let mut ignored = 0;
            for _ in 0..50 {
                let s = c
                    .sample(32, 0.4, Duration::from_secs(10))
                    .await
                    .expect("sample");
                let u = c
                    .update_priorities(s.keys, vec![0.7; 32])
                    .await
                    .expect("update");
                ignored += u.ignored;
            }
            ignored
        })
    };
    let mut acked = 0;
    for a in actors {
        acked += a.await.expect("actor");
    }
    learner.await.expect("learner");
    assert_eq!(acked, 4 * 40 * 8, "every batch acknowledged");
    let info = client(&server, "t").info().await.expect("info");
    assert_eq!(info.inserts_total, u64::from(acked));
    assert_eq!(info.size, 300);
    assert_eq!(info.samples_total, 50 * 32);
    assert_eq!(
        info.priority_updates_total + info.ignored_updates_total,
        50 * 32
    );
    stop(server, shutdown).await;
}

#[tokio::test]
async fn periodic_snapshots_are_written_and_a_renamed_table_refuses_to_start() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = server_config(Some(dir.path()));
    config.replay.snapshot_interval_secs = 1;
    let (server, shutdown, registry) = serve(&config).await;
    client(&server, "t")
        .insert(batch(0, 5, None))
        .await
        .expect("insert");
    let c = client(&server, "t");
    wait_until(WAIT, "a periodic snapshot (every second)", async || {
        c.info().await.is_ok_and(|i| i.last_snapshot_unix_ms > 0)
    })
    .await;
    let text = crossroads_common::metrics::render(&registry);
    assert!(
        !text.contains("crossroads_replay_snapshots_total{result=\"ok\"} 0"),
        "{text}"
    );
    assert!(text.contains("crossroads_replay_snapshot_duration_seconds"));
    stop(server, shutdown).await;

    // The snapshot's table is not the configured one: refuse, naming both,
    // rather than start empty and prune the snapshot later.
    config.replay.table = "renamed".to_owned();
    let err = crossroads_replay::start(&config, None, Shutdown::new())
        .await
        .expect_err("table mismatch");
    let message = err.to_string();
    assert!(
        message.contains("\"t\"") && message.contains("renamed"),
        "{message}"
    );
    config.replay.restore = false;
    let (server, shutdown, _r) = serve(&config).await;
    assert_eq!(server.table("renamed").expect("table").stats().info.size, 0);
    stop(server, shutdown).await;
}
