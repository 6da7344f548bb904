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
use crossroads_transport::grpc::ReplayClient;

use crate::util::{batch, prepared, server_config};

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

/// What a kill -9 leaves: the folder's files as they are on disk now.
fn crash_copy(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("list") {
        let entry = entry.expect("entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("type").is_dir() {
            crash_copy(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).expect("copy");
        }
    }
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
async fn concurrent_appends_share_fsyncs_and_all_become_durable() {
    let dir = tempfile::tempdir().expect("temp dir");
    let metrics = ReplayMetrics::unregistered();
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
        let log = log.clone();
        tasks.push(tokio::spawn(async move {
            log.append("t", &prepared(b * 10, 10, None), u64::from(b) * 10)
                .durable()
                .await
        }));
    }
    for t in tasks {
        t.await.expect("task").expect("durable");
    }
    assert_eq!(metrics.wal_records.get(), 64);
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
