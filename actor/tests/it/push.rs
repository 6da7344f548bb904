//! Pushing to a real replay server on loopback, over gRPC and over
//! iceoryx2; surviving the server's stop and restart.

use std::time::Duration;

use crossroads_actor::{ActorMetrics, PushConfig, Pusher};
use crossroads_common::Shutdown;
use crossroads_config::ActorTransport;
use crossroads_transport::grpc::ReplayClient;
use crossroads_types::TransitionBatch;

use crate::util::{
    actor, actor_config, batches, eventually, replay_config, transport, unique_prefix,
};

fn some_batches(n: usize, size: usize) -> Vec<TransitionBatch> {
    let (mut a, mut v) = actor(&actor_config(4, size), 0);
    batches(&mut a, &mut v, n)
}

fn push_config(kind: ActorTransport, endpoint: &str, prefix: &str, buffer: usize) -> PushConfig {
    PushConfig {
        transport: kind,
        connection: transport(endpoint, prefix),
        table: "t".to_owned(),
        buffer_batches: buffer,
        in_flight: 4,
    }
}

async fn table_size(client: &ReplayClient) -> u64 {
    client.info().await.map(|i| i.size).unwrap_or(0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pushes_reach_a_real_replay_server_over_grpc() {
    let shutdown = Shutdown::new();
    let server =
        crossroads_replay::start(&replay_config("127.0.0.1:0", None), None, shutdown.clone())
            .await
            .expect("replay");
    let endpoint = format!("http://{}", server.local_addr());
    let registry = crossroads_common::metrics::registry("actor").expect("registry");
    let metrics = ActorMetrics::new(Some(&registry), "left").expect("metrics");
    let config = push_config(ActorTransport::Grpc, &endpoint, "unused", 64);
    let pusher = Pusher::start(&config, metrics.clone(), &shutdown).expect("pusher");
    for b in some_batches(5, 20) {
        pusher.push(b);
    }
    let client = ReplayClient::new(&config.connection, "t").expect("client");
    let start = std::time::Instant::now();
    while table_size(&client).await < 100 {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "replay did not grow"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    pusher.close(Duration::from_secs(5)).await;
    assert_eq!(table_size(&client).await, 100);
    assert_eq!(metrics.pushed_total("grpc"), 100);
    let text = crossroads_common::metrics::render(&registry);
    for name in [
        "crossroads_actor_transitions_pushed_total",
        "crossroads_actor_push_latency_seconds_bucket",
        "crossroads_actor_transitions_dropped_total",
        "crossroads_actor_epsilon",
        "crossroads_actor_weights_version",
    ] {
        assert!(text.contains(name), "{name} missing from:\n{text}");
    }
    shutdown.trigger();
    server.join().await.expect("clean stop");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pushes_reach_a_real_replay_server_over_shared_memory() {
    let prefix = unique_prefix("shm");
    let shutdown = Shutdown::new();
    let server = crossroads_replay::start(
        &replay_config("127.0.0.1:0", Some(&prefix)),
        None,
        shutdown.clone(),
    )
    .await
    .expect("replay");
    let metrics = ActorMetrics::new(None, "left").expect("metrics");
    let config = push_config(ActorTransport::Shm, "http://127.0.0.1:1", &prefix, 64);
    let pusher = Pusher::start(&config, metrics.clone(), &shutdown).expect("pusher");
    for b in some_batches(4, 25) {
        pusher.push(b);
    }
    let table = server.table("t").expect("table");
    eventually(Duration::from_secs(20), "100 items over iceoryx2", || {
        table.stats().info.size >= 100
    })
    .await;
    pusher.close(Duration::from_secs(5)).await;
    assert_eq!(table.stats().info.size, 100);
    assert_eq!(metrics.pushed_total("shm"), 100);
    shutdown.trigger();
    server.join().await.expect("clean stop");
}

/// The server stops; the actor keeps pushing into its bounded buffer
/// (dropping the oldest, counted) and retrying; a new server on the same
/// address gets the buffered batches and what follows.
async fn survives_a_restart(kind: ActorTransport) {
    let prefix = unique_prefix("restart");
    let shm = (kind == ActorTransport::Shm).then_some(prefix.as_str());
    let first = Shutdown::new();
    let server = crossroads_replay::start(&replay_config("127.0.0.1:0", shm), None, first.clone())
        .await
        .expect("replay");
    let addr = server.local_addr();
    let endpoint = format!("http://{addr}");
    let metrics = ActorMetrics::new(None, "left").expect("metrics");
    let actor_shutdown = Shutdown::new();
    let label = match kind {
        ActorTransport::Grpc => "grpc",
        ActorTransport::Shm => "shm",
    };
    let config = push_config(kind, &endpoint, &prefix, 3);
    let pusher = Pusher::start(&config, metrics.clone(), &actor_shutdown).expect("pusher");
    let mut all = some_batches(12, 10).into_iter();

    for b in all.by_ref().take(2) {
        pusher.push(b);
    }
    let table = server.table("t").expect("table");
    eventually(Duration::from_secs(20), "the first batches", || {
        table.stats().info.size >= 20
    })
    .await;
    eventually(Duration::from_secs(5), "their acknowledgements", || {
        metrics.pushed_total(label) >= 20
    })
    .await;

    first.trigger();
    server.join().await.expect("first server stops");
    // Five batches into a buffer of three while nobody listens: the two
    // oldest are dropped.
    for b in all.by_ref().take(5) {
        pusher.push(b);
    }
    eventually(Duration::from_secs(10), "failed attempts", || {
        metrics.retries_total(label) >= 2
    })
    .await;
    // A batch out for an attempt goes back to the buffer when the attempt
    // fails; then the buffer holds the newest three and two are dropped.
    eventually(
        Duration::from_secs(10),
        "the two oldest batches dropped",
        || metrics.dropped_total("buffer_full") >= 20,
    )
    .await;
    assert!(pusher.buffered() <= 3);

    let second = Shutdown::new();
    let server =
        crossroads_replay::start(&replay_config(&addr.to_string(), shm), None, second.clone())
            .await
            .expect("replay again, same address");
    for b in all.by_ref().take(2) {
        pusher.push(b);
    }
    let table = server.table("t").expect("table");
    // What the buffer kept and the 2 new ones arrive; whatever did not fit
    // in the buffer is counted.
    eventually(Duration::from_secs(30), "pushes to resume", || {
        table.stats().info.size + metrics.dropped_total("buffer_full") >= 70
    })
    .await;
    pusher.close(Duration::from_secs(5)).await;
    let size = table.stats().info.size;
    let dropped = metrics.dropped_total("buffer_full");
    assert!(size >= 30, "the buffer's batches and the new ones: {size}");
    assert_eq!(
        size + dropped,
        70,
        "every transition after the stop either delivered once or counted as dropped"
    );
    second.trigger();
    server.join().await.expect("second server stops");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_grpc_pusher_survives_a_replay_restart() {
    survives_a_restart(ActorTransport::Grpc).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_shm_pusher_survives_a_replay_restart() {
    survives_a_restart(ActorTransport::Shm).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_acting_loop_delivers_every_transition_it_assembles() {
    let shutdown = Shutdown::new();
    let server =
        crossroads_replay::start(&replay_config("127.0.0.1:0", None), None, shutdown.clone())
            .await
            .expect("replay");
    let endpoint = format!("http://{}", server.local_addr());
    let (mut a, mut v) = actor(&actor_config(4, 24), 0);
    let pusher = Pusher::start(
        &push_config(ActorTransport::Grpc, &endpoint, "unused", 1024),
        a.metrics().clone(),
        &shutdown,
    )
    .expect("pusher");
    let stop = Shutdown::new();
    let (report, pusher) = tokio::task::spawn_blocking(move || {
        let report = a.run(&mut v, Some(&pusher), &stop, Some(150));
        (report, pusher)
    })
    .await
    .expect("acting thread");
    let report = report.expect("run");
    assert_eq!(report.steps, 150);
    assert!(report.transitions > 24, "{report:?}");
    assert!(report.episodes.episodes() > 0);
    pusher.close(Duration::from_secs(10)).await;
    let table = server.table("t").expect("table");
    assert_eq!(
        table.stats().info.size,
        report.transitions,
        "full batches and the last partial one"
    );
    shutdown.trigger();
    server.join().await.expect("clean stop");
}

/// A replay that answers but holds inserts back (its rate limiter, with
/// nobody sampling) slows the acting loop down: it waits, counts the wait,
/// and drops nothing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rate_limited_replay_slows_the_actor_instead_of_losing_batches() {
    let shutdown = Shutdown::new();
    let mut config = replay_config("127.0.0.1:0", None);
    config.replay.min_size_to_sample = 100;
    config.replay.samples_per_insert = 1.0;
    config.replay.rate_tolerance = 200.0;
    let server = crossroads_replay::start(&config, None, shutdown.clone())
        .await
        .expect("replay");
    let endpoint = format!("http://{}", server.local_addr());
    let (mut a, mut v) = actor(&actor_config(4, 24), 0);
    let metrics = a.metrics().clone();
    let pusher = Pusher::start(
        &push_config(ActorTransport::Grpc, &endpoint, "unused", 64),
        metrics.clone(),
        &shutdown,
    )
    .expect("pusher");
    let stop = Shutdown::new();
    let acting_stop = stop.clone();
    let acting = tokio::task::spawn_blocking(move || {
        let report = a.run(&mut v, Some(&pusher), &acting_stop, None);
        (report, pusher)
    });
    let table = server.table("t").expect("table");
    eventually(
        Duration::from_secs(30),
        "the replay to hold inserts back",
        || metrics.backpressure_seconds.get() > 1.0,
    )
    .await;
    let held = table.stats().info.size;
    assert!(held <= 100 + 200 + 24, "the rate limiter let {held} in");
    let steps = metrics.env_steps_total();
    // This sleep is the test: over half a second the actor, held back,
    // takes far fewer than 200 steps.
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(
        metrics.env_steps_total() < steps + 200,
        "the actor kept acting while the replay was behind"
    );
    stop.trigger();
    let (report, pusher) = acting.await.expect("acting thread");
    report.expect("run");
    assert_eq!(metrics.dropped_total("buffer_full"), 0);
    drop(pusher);
    shutdown.trigger();
    server.join().await.expect("clean stop");
}

/// Two actors push over iceoryx2 to a replay whose rate limiter holds
/// inserts back while a slow sampler (the learner's part) drains it. Both
/// get their batches in: iceoryx2 hands out the first publisher's samples
/// while it has any, so without the replay serving publishers in turn the
/// second actor waited for acknowledgements until it gave up on the
/// replay (seen in `crossroads train` with two actors).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_actors_behind_a_rate_limiter_both_get_their_batches_in() {
    let prefix = unique_prefix("fair");
    let shutdown = Shutdown::new();
    let mut config = replay_config("127.0.0.1:0", Some(&prefix));
    config.replay.min_size_to_sample = 100;
    config.replay.samples_per_insert = 1.0;
    config.replay.rate_tolerance = 100.0;
    let server = crossroads_replay::start(&config, None, shutdown.clone())
        .await
        .expect("replay");
    let table = server.table("t").expect("table");
    let mut pushers = Vec::new();
    for _ in 0..2 {
        let metrics = ActorMetrics::new(None, "left").expect("metrics");
        let mut c = push_config(ActorTransport::Shm, "http://127.0.0.1:1", &prefix, 64);
        c.in_flight = 2;
        let pusher = Pusher::start(&c, metrics.clone(), &shutdown).expect("pusher");
        // Far more than the limiter lets in at once: both queues stay full.
        for b in some_batches(40, 25) {
            pusher.push(b);
        }
        pushers.push((pusher, metrics));
    }
    // The sampler: 25 items at a time, so 25 more may go in each time.
    let sampler = {
        let table = table.clone();
        let stop = shutdown.clone();
        tokio::spawn(async move {
            while !stop.is_triggered() {
                let _ = table
                    .sample(25, 0.4, Duration::from_millis(200), &stop)
                    .await;
                // Deliberately slow: the replay's inserts wait for it.
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
    };
    eventually(
        Duration::from_secs(30),
        "one actor's first 500 items in",
        || pushers.iter().any(|(_, m)| m.pushed_total("shm") >= 500),
    )
    .await;
    // Served in turn, the other is close behind (it started later; served
    // first-come, it would still be near 0).
    let counts: Vec<u64> = pushers.iter().map(|(_, m)| m.pushed_total("shm")).collect();
    assert!(
        counts.iter().all(|&n| n >= 250),
        "one actor got its batches in, the other waited: {counts:?}"
    );
    eventually(Duration::from_secs(30), "every batch in", || {
        pushers.iter().all(|(_, m)| m.pushed_total("shm") == 1000)
    })
    .await;
    for (pusher, metrics) in pushers {
        assert_eq!(metrics.dropped_total("buffer_full"), 0);
        assert_eq!(
            metrics.retries_total("shm"),
            0,
            "no batch waited for its ack until the timeout"
        );
        drop(pusher);
    }
    shutdown.trigger();
    let _ = sampler.await;
    server.join().await.expect("clean stop");
}
