//! The write-ahead log: records round trip, a torn tail is cut where it
//! tears, and what a kill -9 leaves on disk (a copy of the folder taken
//! while the server runs) restores every acknowledged insert, once.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_config::{Config, TransportConfig};
use crossroads_replay::wal::{self, Wal, WalConfig};
use crossroads_replay::{ReplayMetrics, RunningServer, TableImage};
use crossroads_test_support::crash_copy;
use crossroads_transport::grpc::ReplayClient;

use crate::util::{WAIT, batch, prepared, server_config};

async fn serve(config: &Config) -> (RunningServer, Shutdown) {
    let shutdown = Shutdown::new();
    let server = crossroads_replay::start(config, None, shutdown.clone())
        .await
        .expect("start");
    (server, shutdown)
}

fn client(server: &RunningServer) -> ReplayClient {
    let transport = TransportConfig {
        replay_endpoint: format!("http://{}", server.local_addr()),
        request_timeout_ms: 5_000,
        ..TransportConfig::default()
    };
    ReplayClient::new(&transport, "t").expect("client")
}

async fn stop(server: RunningServer, shutdown: Shutdown) {
    shutdown.trigger();
    tokio::time::timeout(Duration::from_secs(15), server.join())
        .await
        .expect("stops")
        .expect("clean stop");
}

/// Items by reward (the tag of `batch`), so lost or doubled transitions
/// show by tag.
fn tags(image: &TableImage) -> BTreeMap<u32, usize> {
    let mut count = BTreeMap::new();
    for r in &image.items.rewards {
        *count.entry(*r as u32).or_default() += 1;
    }
    count
}

fn segment_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir.join("wal"))
        .map(|d| {
            d.map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

#[test]
fn records_round_trip_and_a_torn_tail_keeps_every_whole_record_before_it() {
    let images: Vec<TableImage> = (0..3)
        .map(|b| prepared(b * 10, 4 + b, None).to_image(100 + u64::from(b) * 10))
        .collect();
    let mut bytes = wal::segment_header().to_vec();
    let mut ends = Vec::new();
    for image in &images {
        wal::encode_record(&mut bytes, "t", image);
        ends.push(bytes.len());
    }
    let whole = wal::decode_segment(&bytes).expect("valid");
    assert_eq!(whole.torn, None);
    assert_eq!(whole.valid_len, bytes.len());
    let decoded: Vec<&TableImage> = whole.records.iter().map(|(_, i)| i).collect();
    assert_eq!(decoded, images.iter().collect::<Vec<_>>());
    for (name, image) in &whole.records {
        assert_eq!(name, "t");
        let (first_key, batch) =
            crossroads_replay::PreparedBatch::from_image(image.clone()).expect("holds together");
        assert_eq!(batch.to_image(first_key), *image);
    }

    // Cut anywhere: the whole records before the cut, no more, no panic.
    for cut in 16..bytes.len() {
        let d = wal::decode_segment(&bytes[..cut]).expect("header intact");
        let expected = ends.iter().filter(|e| **e <= cut).count();
        assert_eq!(d.records.len(), expected, "cut at {cut}");
        assert_eq!(
            d.torn.is_some(),
            !ends.contains(&cut) && cut > 16,
            "cut at {cut}"
        );
    }
    // A flipped bit in the second record: the first stays, reading stops.
    let mut flipped = bytes.clone();
    flipped[ends[0] + 20] ^= 0x10;
    let d = wal::decode_segment(&flipped).expect("header intact");
    assert_eq!(d.records.len(), 1);
    assert!(d.torn.expect("torn").contains("checksum"));
    // A damaged header is an error, not an empty log.
    let mut bad = bytes.clone();
    bad[3] ^= 1;
    assert!(
        wal::decode_segment(&bad)
            .expect_err("bad magic")
            .contains("magic")
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_appends_share_fsyncs_and_are_stored_at_the_keys_they_are_logged_at() {
    let dir = tempfile::tempdir().expect("temp dir");
    let metrics = ReplayMetrics::unregistered();
    let table = std::sync::Arc::new(crate::util::table(1000, 0.0));
    let log = std::sync::Arc::new(
        Wal::open(
            WalConfig {
                dir: dir.path().join("wal"),
                sync_interval: Duration::from_millis(2),
                sync_bytes: 1 << 20,
            },
            metrics.clone(),
        )
        .expect("open"),
    );
    let mut tasks = Vec::new();
    for b in 0..64u32 {
        let (log, table) = (log.clone(), table.clone());
        tasks.push(tokio::spawn(async move {
            let batch = prepared(b * 10, 10, None);
            let reservation = table.reserve_now(&batch).expect("room");
            log.append(reservation, batch).durable().await
        }));
    }
    for t in tasks {
        t.await.expect("task").expect("durable");
    }
    assert_eq!(metrics.wal_records.get(), 64);
    assert_eq!(table.stats().info.size, 640, "each stored once durable");
    let groups = metrics.wal_sync_seconds.get_sample_count();
    assert!(
        (1..64).contains(&groups),
        "64 concurrent records took {groups} fsyncs; group commit shares them"
    );
    let sealed = log.rotate().expect("rotate");
    log.close();
    let segments = segment_names(dir.path());
    assert_eq!(segments, ["wal-0000000001.log"]);
    assert_eq!(sealed, 1);
    let bytes = std::fs::read(dir.path().join("wal").join(&segments[0])).expect("read");
    let d = wal::decode_segment(&bytes).expect("valid");
    assert_eq!((d.records.len(), d.torn), (64, None));
    // The log's keys are the table's: one after another in log order, and
    // each record's batch is the one the table holds at those keys.
    let held = table.image();
    let mut next = 0;
    for (_, image) in &d.records {
        let (first_key, batch) =
            crossroads_replay::PreparedBatch::from_image(image.clone()).expect("holds together");
        assert_eq!(first_key, next);
        let at = first_key as usize;
        assert_eq!(
            held.items.rewards[at..at + batch.len()],
            image.items.rewards[..],
            "the batch at keys {first_key}.."
        );
        next += batch.len() as u64;
    }
}

#[tokio::test]
async fn a_kill_9_loses_no_acknowledged_insert_and_replays_each_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let live = dir.path().join("live");
    let config = server_config(Some(&live));
    let (server, shutdown) = serve(&config).await;
    let c = client(&server);
    for b in 0..3 {
        c.insert(batch(b * 10, 10, None)).await.expect("acked");
    }
    // A snapshot holds the first three batches and trims the log ...
    c.snapshot().await.expect("snapshot");
    assert!(
        segment_names(&live).is_empty(),
        "{:?}",
        segment_names(&live)
    );
    // ... two more are acknowledged after it: only the log has them.
    for b in 3..5 {
        c.insert(batch(b * 10, 10, None)).await.expect("acked");
    }
    let before = server.table("t").expect("table").image();
    let crashed = dir.path().join("crashed");
    crash_copy(&live, &crashed);
    // The log's segment still there from before the snapshot (as if the
    // crash came between the snapshot's rename and the deletion) must not
    // double anything: the snapshot holds its records by key.
    stop(server, shutdown).await;

    let (server, shutdown) = serve(&server_config(Some(&crashed))).await;
    let after = server.table("t").expect("table").image();
    assert_eq!(
        tags(&after),
        tags(&before),
        "every acknowledged transition, once"
    );
    assert_eq!(after.items, before.items);
    assert_eq!(after.next_key, before.next_key);
    // The replayed log went into a snapshot at start; the log is empty.
    assert!(
        segment_names(&crashed).is_empty(),
        "{:?}",
        segment_names(&crashed)
    );
    stop(server, shutdown).await;
}

#[tokio::test]
async fn a_segment_left_from_before_a_snapshot_doubles_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let live = dir.path().join("live");
    let config = server_config(Some(&live));
    let (server, shutdown) = serve(&config).await;
    let c = client(&server);
    for b in 0..4 {
        c.insert(batch(b * 10, 10, None)).await.expect("acked");
    }
    let crashed = dir.path().join("crashed");
    crash_copy(&live, &crashed);
    // The snapshot the crash cut short of its log deletion: written, but
    // the segments it holds are still there.
    c.snapshot().await.expect("snapshot");
    for entry in std::fs::read_dir(&live).expect("list") {
        let entry = entry.expect("entry");
        if entry.file_name().to_string_lossy().ends_with(".crsnap") {
            std::fs::copy(entry.path(), crashed.join(entry.file_name())).expect("copy");
        }
    }
    let before = server.table("t").expect("table").image();
    stop(server, shutdown).await;
    assert_eq!(segment_names(&crashed).len(), 1);

    let (server, shutdown) = serve(&server_config(Some(&crashed))).await;
    let after = server.table("t").expect("table").image();
    assert_eq!(tags(&after), tags(&before));
    assert_eq!(after.len(), 40);
    stop(server, shutdown).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_batch_whose_log_write_fails_is_never_sampled_and_its_resend_is_stored_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let live = dir.path().join("live");
    let (server, shutdown) = serve(&server_config(Some(&live))).await;
    let c = client(&server);
    let table = server.table("t").expect("table");
    // The segment the log's writer creates first is taken (by a folder):
    // the batch's write fails as on a full disk, even for root.
    let blocker = live.join("wal").join("wal-0000000001.log");
    std::fs::create_dir(&blocker).expect("take the first segment's name");
    // A learner samples all along, until the batch is sent again.
    let enough = Shutdown::new();
    let sampler = tokio::spawn({
        let (table, enough) = (table.clone(), enough.clone());
        async move {
            let mut keys = Vec::new();
            while !enough.is_triggered() {
                if let Ok(s) = table
                    .sample(1, 0.0, Duration::from_millis(5), &enough)
                    .await
                {
                    keys.extend(s.keys);
                }
            }
            keys
        }
    });
    let refused = c
        .insert(batch(0, 10, None))
        .await
        .expect_err("its log write fails");
    assert_eq!(refused.code(), Some(tonic::Code::Unavailable), "{refused}");
    assert!(refused.to_string().contains("nothing stored"), "{refused}");
    assert_eq!(table.stats().info.size, 0, "not in the table");
    // Room again: the actor sends the batch again until it is stored.
    std::fs::remove_dir(&blocker).expect("give the name back");
    enough.trigger();
    let sampled = sampler.await.expect("sampler");
    assert!(
        sampled.is_empty(),
        "sampled while unacknowledged: {sampled:?}"
    );
    let deadline = tokio::time::Instant::now() + WAIT;
    let ack = loop {
        match c.insert(batch(0, 10, None)).await {
            Ok(ack) => break ack,
            // Refused for a second after the failure, nothing stored.
            Err(e) => {
                assert!(e.to_string().contains("nothing stored"), "{e}");
                assert!(tokio::time::Instant::now() < deadline, "never stored: {e}");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    };
    assert_eq!((ack.inserted, ack.table_size), (10, 10));
    let held = table.image();
    assert_eq!(held.len(), 10, "one batch's items, once");
    assert_eq!(
        tags(&held),
        (0..10).map(|t| (t, 1)).collect::<BTreeMap<u32, usize>>()
    );
    // The log holds it once, at the keys the table gave it, so a crash
    // now restores it once.
    let segments = segment_names(&live);
    assert_eq!(segments, ["wal-0000000001.log"]);
    let bytes = std::fs::read(live.join("wal").join(&segments[0])).expect("read");
    let logged = wal::decode_segment(&bytes).expect("valid").records;
    assert_eq!(logged.len(), 1);
    assert_eq!(
        (logged[0].1.next_key, logged[0].1.len()),
        (held.next_key, 10)
    );
    let crashed = dir.path().join("crashed");
    crash_copy(&live, &crashed);
    stop(server, shutdown).await;
    let (server, shutdown) = serve(&server_config(Some(&crashed))).await;
    let after = server.table("t").expect("table").image();
    assert_eq!(tags(&after), tags(&held));
    assert_eq!(after.next_key, held.next_key);
    stop(server, shutdown).await;
}

#[tokio::test]
async fn without_restore_the_log_is_set_aside_not_replayed_later() {
    let dir = tempfile::tempdir().expect("temp dir");
    let live = dir.path().join("live");
    let (server, shutdown) = serve(&server_config(Some(&live))).await;
    client(&server)
        .insert(batch(0, 10, None))
        .await
        .expect("acked");
    let crashed = dir.path().join("crashed");
    crash_copy(&live, &crashed);
    stop(server, shutdown).await;

    let mut fresh = server_config(Some(&crashed));
    fresh.replay.restore = false;
    let (server, shutdown) = serve(&fresh).await;
    assert!(server.table("t").expect("table").image().is_empty());
    stop(server, shutdown).await;
    let names = segment_names(&crashed);
    assert!(
        names.iter().any(|n| n.ends_with(".log.skipped")),
        "set aside, kept: {names:?}"
    );
    // Restoring later finds the clean-stop snapshot (empty), not the old log.
    let (server, shutdown) = serve(&server_config(Some(&crashed))).await;
    assert!(server.table("t").expect("table").image().is_empty());
    stop(server, shutdown).await;
}

#[tokio::test]
async fn with_the_log_off_a_crash_loses_what_came_after_the_snapshot() {
    // The property the log exists for, shown by its absence.
    let dir = tempfile::tempdir().expect("temp dir");
    let live = dir.path().join("live");
    let mut config = server_config(Some(&live));
    config.replay.wal = false;
    let (server, shutdown) = serve(&config).await;
    let c = client(&server);
    c.insert(batch(0, 10, None)).await.expect("acked");
    c.snapshot().await.expect("snapshot");
    c.insert(batch(10, 10, None)).await.expect("acked");
    let crashed = dir.path().join("crashed");
    crash_copy(&live, &crashed);
    stop(server, shutdown).await;
    let mut after_crash = server_config(Some(&crashed));
    after_crash.replay.wal = false;
    let (server, shutdown) = serve(&after_crash).await;
    assert_eq!(server.table("t").expect("table").image().len(), 10);
    stop(server, shutdown).await;
}
