//! iceoryx2 ingest: a real second process publishes batches into the
//! server's table; a publisher without a server fails instead of hanging.

use std::time::{Duration, Instant};

use crossroads_common::Shutdown;
use crossroads_config::TransportConfig;
use crossroads_transport::shm::{ShmBatchPublisher, ShmError};

use crossroads_types::ValidBatch;

use crate::util::{SPEC_LEN, batch, obs, server_config, unique_prefix, valid};

const CHILD_PREFIX: &str = "CROSSROADS_TEST_SHM_PREFIX";

fn transport(prefix: &str) -> TransportConfig {
    TransportConfig {
        shm_prefix: prefix.to_owned(),
        shm_send_timeout_ms: 2_000,
        ..TransportConfig::default()
    }
}

/// The publishing side: `batches_from_another_process_land_in_the_table`
/// run again, in a child process of this same test binary, with
/// [`CHILD_PREFIX`] set.
fn publish_as_child(prefix: &str) {
    let mut publisher = ShmBatchPublisher::new(&transport(prefix), "t").expect("publisher");
    let start = Instant::now();
    while publisher.subscribers() == 0 {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no replay server appeared"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    for b in 0..5u32 {
        publisher
            .send(u64::from(b), &valid(b * 10, 10, None))
            .expect("send");
    }
    let acks = publisher
        .flush(Duration::from_secs(20))
        .expect("every batch answered");
    assert_eq!(acks.len(), 5);
    for (i, ack) in acks.iter().enumerate() {
        assert_eq!(ack.batch_id, i as u64);
        assert_eq!(
            ack.outcome,
            Ok((10, 10 * (i as u64 + 1))),
            "stored, in order"
        );
    }
    // A batch the table refuses (another observation kind) is answered with
    // its rejection, not silently dropped.
    let mut other = batch(50, 10, None);
    other.layout.kind = "other".to_owned();
    let other = ValidBatch::new(other).expect("valid, only not the table's");
    publisher.send(5, &other).expect("send");
    let acks = publisher.flush(Duration::from_secs(20)).expect("answered");
    assert_eq!(acks.len(), 1);
    assert_eq!(acks[0].outcome, Err(crossroads_types::RejectReason::Spec));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batches_from_another_process_land_in_the_table() {
    if let Ok(prefix) = std::env::var(CHILD_PREFIX) {
        publish_as_child(&prefix);
        return;
    }
    let prefix = unique_prefix("ingest");
    let mut config = server_config(None);
    config.replay.shm_ingest = true;
    config.transport = transport(&prefix);
    let shutdown = Shutdown::new();
    let server = crossroads_replay::start(&config, None, shutdown.clone())
        .await
        .expect("start");

    let child = {
        let prefix = prefix.clone();
        tokio::task::spawn_blocking(move || {
            std::process::Command::new(std::env::current_exe().expect("test binary"))
                .args([
                    "shm::batches_from_another_process_land_in_the_table",
                    "--exact",
                    "--nocapture",
                    "--test-threads=1",
                ])
                .env(CHILD_PREFIX, &prefix)
                .output()
        })
    };
    let out = tokio::time::timeout(Duration::from_secs(60), child)
        .await
        .expect("child finished")
        .expect("task")
        .expect("child ran");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "child failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("1 passed"),
        "the child ran the publisher:\n{stdout}"
    );

    let table = server.table("t").expect("table");
    let start = Instant::now();
    while table.stats().info.size < 50 {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "only {} items arrived",
            table.stats().info.size
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let image = table.image();
    let tags: Vec<f32> = (0..50).map(|t| t as f32).collect();
    assert_eq!(
        image.items.rewards, tags,
        "every batch, in order, nothing twice"
    );
    let s = table
        .sample(20, 0.4, Duration::from_secs(1), &shutdown)
        .await
        .expect("sample");
    let mut values = vec![0.0; SPEC_LEN];
    for i in 0..s.batch.len() {
        let tag = s.batch.columns.rewards[i] as u32;
        let tr = s.batch.transition(i).expect("in range");
        s.batch
            .observations
            .decode_into(tr.observation as usize, &mut values)
            .expect("decodes");
        assert_eq!(values, obs(tag));
    }
    shutdown.trigger();
    tokio::time::timeout(Duration::from_secs(15), server.join())
        .await
        .expect("stops")
        .expect("clean stop");
}

#[test]
fn a_publisher_without_a_server_fails_fast() {
    let prefix = unique_prefix("no-server");
    let mut publisher = ShmBatchPublisher::new(&transport(&prefix), "t").expect("publisher");
    assert_eq!(publisher.subscribers(), 0);
    let start = Instant::now();
    let err = publisher
        .send(0, &valid(0, 3, None))
        .expect_err("nobody listens");
    assert!(matches!(err, ShmError::NoSubscriber { .. }), "{err:?}");
    assert!(start.elapsed() < Duration::from_secs(2));
    // An invalid batch cannot be sent: it never becomes a `ValidBatch`.
    let mut bad = batch(0, 3, None);
    bad.columns.rewards[1] = f32::NAN;
    let err = ValidBatch::new(bad).expect_err("invalid");
    assert!(err.to_string().contains("rewards[1]"), "{err}");
    assert_eq!(publisher.in_flight().count(), 0);
    assert!(
        publisher
            .flush(Duration::from_millis(10))
            .expect("nothing pending")
            .is_empty()
    );
}

#[test]
fn a_full_queue_fails_the_send_after_its_timeout_instead_of_hanging() {
    let prefix = unique_prefix("full");
    let mut config = transport(&prefix);
    config.shm_buffer = 2;
    config.shm_send_timeout_ms = 300;
    // A "server" that subscribes and never reads.
    let node = crossroads_transport::shm::node().expect("node");
    let service =
        crossroads_transport::shm::open_batch_service(&node, &config, "t").expect("service");
    let stuck = service
        .subscriber_builder()
        .buffer_size(2)
        .create()
        .expect("subscriber");
    let mut publisher = ShmBatchPublisher::new(&config, "t").expect("publisher");
    // It connects (as a polling server does), then reads nothing.
    assert!(!stuck.has_samples().expect("connected"));
    publisher.send(0, &valid(0, 2, None)).expect("queued");
    publisher.send(1, &valid(2, 2, None)).expect("queued");
    let start = Instant::now();
    let err = publisher
        .send(2, &valid(4, 2, None))
        .expect_err("queue full");
    let waited = start.elapsed();
    assert!(
        matches!(err, ShmError::Full { .. }),
        "{err:?} after {waited:?}"
    );
    assert!(
        waited >= Duration::from_millis(300) && waited < Duration::from_secs(5),
        "{waited:?}"
    );
    let err = publisher
        .flush(Duration::from_millis(100))
        .expect_err("nobody answers");
    assert!(
        matches!(err, ShmError::Unacknowledged { pending: 2, .. }),
        "{err:?}"
    );
}
