//! Faults as an operator meets them, on real processes: kill -9 of the
//! replay server, the learner and actors at random moments, a replay disk
//! that fills up, and network partitions. Each test counts exactly what
//! was lost (by batch tag or version) and how long recovery took, and
//! prints it.
//!
//! The quick version runs in `make test`; `CROSSROADS_LONG_FAULTS=1` (as
//! `make faults` sets) repeats every kill many more times.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use crossroads_config::TransportConfig;
use crossroads_transport::grpc::ReplayClient;
use crossroads_transport::learner_client::LearnerClient;
use crossroads_types::{ObservationEncoding, ObservationLayout, Transition, TransitionBatch};
use rand::{RngExt, SeedableRng};
use std::sync::Mutex;

use crossroads_test_support::gates::{self, Need};
use crossroads_test_support::{RoleProcess, crash_copy};

/// Whether this is the long suite: `CROSSROADS_LONG_FAULTS=1`.
fn long() -> bool {
    gates::is_on(gates::LONG_FAULTS)
}

/// Kill rounds: `quick` in `make test`, `long` in the long suite.
fn rounds(quick: usize, long_rounds: usize) -> usize {
    if long() { long_rounds } else { quick }
}

/// The seed of this run's random moments, printed so a failure replays.
fn rng(test: &str) -> rand::rngs::StdRng {
    let seed = std::env::var("CROSSROADS_FAULT_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(1, |d| d.as_nanos() as u64)
        });
    eprintln!("{test}: CROSSROADS_FAULT_SEED={seed}");
    rand::rngs::StdRng::seed_from_u64(seed)
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime")
}

/// Ten transitions whose rewards all carry `tag`, so the stored items
/// tell which batches came through.
fn tagged(tag: u32) -> TransitionBatch {
    let layout = ObservationLayout::new("toy", 4, 4, 2, 0);
    let mut b = TransitionBatch::new(layout, 5, ObservationEncoding::SparseF32);
    let mut grid = vec![0.0; 32];
    let mut current = b.push_observation(&grid);
    for i in 0..10 {
        grid[i * 3 % 32] = tag as f32;
        let next = b.push_observation(&grid);
        b.push(Transition {
            observation: current,
            action: (i % 5) as u32,
            reward: tag as f32,
            discount: 0.99,
            priority: 1.0,
            next_observation: next,
        });
        current = next;
    }
    b
}

fn start_replay(dir: &Path) -> (RoleProcess, String, Duration) {
    let started = Instant::now();
    let p = crate::crossroads().spawn_role(&[
        "replay".as_ref(),
        "--listen".as_ref(),
        "127.0.0.1:0".as_ref(),
        "--no-shm".as_ref(),
        "--capacity".as_ref(),
        "1000000".as_ref(),
        "--table".as_ref(),
        "faults".as_ref(),
        "--snapshot-dir".as_ref(),
        dir.as_os_str(),
    ]);
    let addr = p.addr("replay server listening");
    (p, addr, started.elapsed())
}

fn replay_client(addr: &str) -> ReplayClient {
    let transport = TransportConfig {
        replay_endpoint: format!("http://{addr}"),
        request_timeout_ms: 5_000,
        ..TransportConfig::default()
    };
    ReplayClient::new(&transport, "faults").expect("client")
}

/// Transitions held by the server, by tag: it writes a snapshot on
/// request, which is read back here.
fn stored(rt: &tokio::runtime::Runtime, addr: &str) -> BTreeMap<u32, usize> {
    let written = rt
        .block_on(replay_client(addr).snapshot())
        .expect("snapshot on request");
    let tables = crossroads_replay::snapshot::read(Path::new(&written.path)).expect("readable");
    let mut count = BTreeMap::new();
    for (_, image) in tables {
        for r in &image.items.rewards {
            *count.entry(*r as u32).or_default() += 1;
        }
    }
    count
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v.get(v.len() / 2).copied().unwrap_or_default()
}

#[test]
fn the_replay_killed_at_random_moments_loses_no_acknowledged_transition() {
    let rounds = rounds(3, 25);
    let mut rng = rng("replay kill -9");
    let dir = tempfile::tempdir().expect("temp dir");
    let rt = runtime();
    // Clients connect lazily, on this runtime.
    let _enter = rt.enter();
    let next_tag = Arc::new(AtomicU32::new(1));
    let mut acked_all = BTreeSet::new();
    let (mut recoveries, mut unacked_stored) = (Vec::new(), 0usize);
    for round in 0..=rounds {
        let (replay, addr, recovery) = start_replay(dir.path());
        if round > 0 {
            recoveries.push(recovery);
        }
        // Everything acknowledged before every kill so far is there, once.
        let held = stored(&rt, &addr);
        let lost: Vec<u32> = acked_all
            .iter()
            .filter(|t| held.get(t) != Some(&10))
            .copied()
            .collect();
        assert!(
            lost.is_empty(),
            "round {round}: {} acknowledged batches lost or partial: {lost:?}",
            lost.len()
        );
        assert!(
            held.values().all(|n| *n == 10),
            "a batch stored twice or in part"
        );
        unacked_stored = held.keys().filter(|t| !acked_all.contains(t)).count();
        if round == rounds {
            replay.terminate();
            break;
        }
        // Four actors insert until the kill, at a random moment.
        let acked = Arc::new(Mutex::new(Vec::new()));
        let actors: Vec<_> = (0..4)
            .map(|_| {
                let (client, acked, next_tag) =
                    (replay_client(&addr), acked.clone(), next_tag.clone());
                rt.spawn(async move {
                    loop {
                        let tag = next_tag.fetch_add(1, Ordering::Relaxed);
                        match client.insert(tagged(tag)).await {
                            Ok(ack) if ack.inserted == 10 => acked.lock().expect("lock").push(tag),
                            Ok(ack) => panic!("partial insert {ack:?}"),
                            Err(_) => return,
                        }
                    }
                })
            })
            .collect();
        // The kill comes at a random moment after the first
        // acknowledgement (on a loaded machine the first can take longer
        // than any fixed pause).
        wait_until(
            &format!("round {round}: a first acknowledged insert"),
            Duration::from_secs(60),
            || acked.lock().expect("lock").len(),
            |n| *n > 0,
        );
        std::thread::sleep(Duration::from_millis(rng.random_range(0..750)));
        replay.kill9();
        for a in actors {
            rt.block_on(a).expect("actor task");
        }
        let acked = std::mem::take(&mut *acked.lock().expect("lock"));
        assert!(
            !acked.is_empty(),
            "round {round}: nothing acknowledged before the kill"
        );
        acked_all.extend(acked);
    }
    eprintln!(
        "faults: replay kill -9 x{rounds}: {} batches ({} transitions) acknowledged, 0 lost; \
         {unacked_stored} stored without their acknowledgement (in flight at a kill); \
         restart to serving: median {:?}, max {:?}",
        acked_all.len(),
        acked_all.len() * 10,
        median(recoveries.clone()),
        recoveries.iter().max().copied().unwrap_or_default(),
    );
}

fn learner_client(addr: &str) -> LearnerClient {
    LearnerClient::new(
        &format!("http://{addr}"),
        &crossroads_transport::security::ClientSecurity::none(),
        Duration::from_secs(10),
    )
    .expect("client")
}

#[test]
fn the_learner_killed_at_random_moments_restarts_from_a_whole_checkpoint_above_every_version() {
    let rounds = rounds(3, 20);
    let mut rng = rng("learner kill -9");
    let dir = tempfile::tempdir().expect("temp dir");
    let rt = runtime();
    // Clients connect lazily, on this runtime.
    let _enter = rt.enter();
    let replay = crate::crossroads().spawn_role(&[
        "replay",
        "--listen",
        "127.0.0.1:0",
        "--no-shm",
        "--capacity",
        "5000",
    ]);
    let replay_addr = replay.addr("replay server listening");
    let config = {
        let mut c = crossroads_config::Config::default();
        c.sim.action_set = "sequential".to_owned();
        c.learner.hidden = vec![32];
        crossroads_actor::resolve_observation(&mut c.sim).expect("a built-in pairing");
        c
    };
    let spec = crossroads_learner::TrainerConfig::from_config(&config.sim, &config.learner)
        .expect("valid")
        .spec;
    rt.block_on(async {
        let client = ReplayClient::new(
            &TransportConfig {
                replay_endpoint: format!("http://{replay_addr}"),
                ..TransportConfig::default()
            },
            "transitions",
        )?;
        crossroads_learner::bench::fill_replay(&client, &spec, 1_000).await
    })
    .expect("fill the replay");
    let ckpts = dir.path().join("ckpts");
    let args: Vec<String> = [
        "--set",
        "sim.action_set=sequential",
        "--set",
        "learner.hidden=[32]",
        "--set",
        "learner.batch_size=16",
        "--set",
        "learner.publish_every=2",
        // A checkpoint every few updates: many kills land in a write.
        "--set",
        "learner.checkpoint_every=3",
        "learner",
        "--listen",
        "127.0.0.1:0",
        "--no-shm",
        "--replay",
    ]
    .into_iter()
    .map(str::to_owned)
    .chain([
        format!("http://{replay_addr}"),
        "--checkpoint-dir".to_owned(),
        ckpts.display().to_string(),
    ])
    .collect();
    let (mut highest, mut recoveries) = (0u64, Vec::new());
    for round in 0..=rounds {
        let started = Instant::now();
        let learner = crate::crossroads().spawn_role(&args);
        let addr = learner.addr("learner listening");
        let c = learner_client(&addr);
        let status = rt.block_on(c.status()).expect("status");
        if round > 0 {
            recoveries.push(started.elapsed());
            assert!(
                status.weights_version > highest,
                "round {round}: restarted at version {} after {highest} was published",
                status.weights_version
            );
            assert!(
                status.update_step > 0,
                "resumed, not started over: {status:?}"
            );
        }
        if round == rounds {
            learner.terminate();
            break;
        }
        // A first checkpoint (every 3 updates) before the first kill, then
        // a random moment.
        wait_until(
            &format!("round {round}: a checkpoint written"),
            Duration::from_secs(60),
            || rt.block_on(c.status()).map_or(0, |s| s.update_step),
            |u| *u >= 3,
        );
        std::thread::sleep(Duration::from_millis(rng.random_range(0..1200)));
        // The highest version published before the kill; it may publish
        // more between this call and the kill, which the lease covers too.
        highest = rt.block_on(c.status()).expect("status").weights_version;
        let log = learner.drain();
        assert!(
            !log.iter().any(|l| l.contains("cannot resume")),
            "round {round}: a partial checkpoint was tried: {log:?}"
        );
        learner.kill9();
    }
    let leftovers: Vec<String> = std::fs::read_dir(&ckpts)
        .expect("list")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(
        leftovers.is_empty(),
        "interrupted writes cleaned up: {leftovers:?}"
    );
    replay.terminate();
    eprintln!(
        "faults: learner kill -9 x{rounds}: every restart resumed a whole checkpoint, versions \
         only increased (last seen {highest}); restart to serving: median {:?}, max {:?}",
        median(recoveries.clone()),
        recoveries.iter().max().copied().unwrap_or_default(),
    );
}

/// The settings of the tests that run a whole small training (every role
/// takes all of them): the sequential action set, a tiny network trained on
/// small batches and published often, the `faults` table.
const SMALL_RUN: [&str; 10] = [
    "--set",
    "sim.action_set=sequential",
    "--set",
    "learner.hidden=[32]",
    "--set",
    "replay.table=faults",
    "--set",
    "learner.batch_size=16",
    "--set",
    "learner.publish_every=5",
];

/// An actor of the actor test: index `index` of 2, pushing and following
/// weights over `transport` (shm or grpc), its metrics on a free port.
/// `common` are the run's settings.
fn start_actor(
    common: &[&str],
    index: usize,
    transport: &str,
    replay: &str,
    learner: &str,
) -> (RoleProcess, String) {
    let index = index.to_string();
    let own = [
        "--set",
        "telemetry.metrics=true",
        "--set",
        "telemetry.metrics_addr=127.0.0.1:0",
        "actor",
        "--transport",
        transport,
        "--weights",
        transport,
        "--index",
        &index,
        "--count",
        "2",
        "--envs",
        "4",
        "--replay",
        replay,
        "--learner",
        learner,
    ];
    let p = crate::crossroads().spawn_role(&[common, &own[..]].concat());
    let metrics = p.addr("serving metrics");
    (p, metrics)
}

#[test]
fn actors_killed_at_random_moments_leave_the_replay_and_the_learner_training() {
    let rounds = rounds(4, 20);
    let mut rng = rng("actor kill -9");
    let rt = runtime();
    let _enter = rt.enter();
    // Its own shared-memory services, apart from other tests'.
    let prefix = format!(
        "transport.shm_prefix=crossroads/faults-{}",
        std::process::id()
    );
    let common = [
        &SMALL_RUN[..],
        &["--set", &prefix, "--set", "replay.min_size_to_sample=200"],
    ]
    .concat();
    // Shared memory on: one actor writes into the replay's memory and
    // reads the learner's, and is killed in the middle of it.
    let replay = crate::crossroads().spawn_role(
        &[
            &common[..],
            &[
                "--set",
                "telemetry.metrics=true",
                "--set",
                "telemetry.metrics_addr=127.0.0.1:0",
                "replay",
                "--listen",
                "127.0.0.1:0",
                "--capacity",
                "50000",
                "--table",
                "faults",
            ],
        ]
        .concat(),
    );
    let [replay_addr, replay_metrics] =
        replay.addrs(["replay server listening", "serving metrics"]);
    let replay_url = format!("http://{replay_addr}");
    let learner = crate::crossroads().spawn_role(
        &[
            &common[..],
            &[
                "learner",
                "--listen",
                "127.0.0.1:0",
                "--replay",
                &replay_url,
            ],
        ]
        .concat(),
    );
    let learner_addr = learner.addr("learner listening");
    let learner_url = format!("http://{learner_addr}");
    let learner_rpc = learner_client(&learner_addr);
    let status = || {
        rt.block_on(learner_rpc.status())
            .expect("the learner answers")
    };
    // Actor 0 over shared memory, actor 1 over gRPC: the replay counts
    // inserts by transport, so each actor's deliveries are told apart.
    let transports = ["shm", "grpc"];
    let inserted = |t: &str| {
        scrape_where(
            &replay_metrics,
            "crossroads_replay_inserts_total",
            &format!("transport=\"{t}\""),
        )
        .unwrap_or(0.0)
    };
    let mut actors: Vec<(RoleProcess, String)> = transports
        .iter()
        .enumerate()
        .map(|(i, t)| start_actor(&common, i, t, &replay_url, &learner_url))
        .collect();
    for t in transports {
        wait_until(
            &format!("the {t} actor pushing"),
            Duration::from_secs(90),
            || inserted(t),
            |n| *n > 0.0,
        );
    }
    wait_until(
        "the learner training",
        Duration::from_secs(90),
        || status().update_step,
        |u| *u > 0,
    );
    let (mut recoveries, mut in_flight, mut survivor_pushed) = (Vec::new(), 0.0, 0.0);
    for round in 0..rounds {
        std::thread::sleep(Duration::from_millis(rng.random_range(500..3000)));
        let victim = rng.random_range(0..2usize);
        let other = transports[1 - victim];
        let (proc, metrics) = actors.remove(victim);
        // What it had made but not delivered, a moment before the kill:
        // an actor's buffer is not durable, and is lost with it.
        let made = scrape(&metrics, "crossroads_actor_transitions_assembled_total").unwrap_or(0.0);
        let pushed = scrape(&metrics, "crossroads_actor_transitions_pushed_total").unwrap_or(0.0);
        in_flight += made - pushed;
        let (updates, others) = (status().update_step, inserted(other));
        proc.kill9();
        // The replay and the learner go on without it.
        let restarted = Instant::now();
        actors.insert(
            victim,
            start_actor(
                &common,
                victim,
                transports[victim],
                &replay_url,
                &learner_url,
            ),
        );
        let fresh = actors[victim].1.clone();
        wait_until(
            &format!(
                "round {round}: the restarted {} actor pushing",
                transports[victim]
            ),
            Duration::from_secs(60),
            || scrape(&fresh, "crossroads_actor_transitions_pushed_total").unwrap_or(0.0),
            |p| *p > 0.0,
        );
        recoveries.push(restarted.elapsed());
        wait_until(
            &format!("round {round}: the restarted actor on published weights"),
            Duration::from_secs(60),
            || scrape(&fresh, "crossroads_actor_weights_version").unwrap_or(0.0),
            |v| *v >= 1.0,
        );
        // Both went on through the kill (waited for, not sampled once: a
        // loaded machine may pause either for a moment).
        wait_until(
            &format!("round {round}: the {other} actor pushing on"),
            Duration::from_secs(60),
            || inserted(other),
            |n| *n > others,
        );
        survivor_pushed += inserted(other) - others;
        wait_until(
            &format!("round {round}: the learner training on"),
            Duration::from_secs(60),
            || status().update_step,
            |u| *u > updates,
        );
    }
    let rejected = scrape(&replay_metrics, "crossroads_replay_rejections_total").unwrap_or(0.0);
    assert_eq!(rejected, 0.0, "no torn or partial batch reached the replay");
    let [shm, grpc] = transports.map(inserted);
    for (p, _) in actors {
        p.terminate();
    }
    learner.terminate();
    replay.terminate();
    eprintln!(
        "faults: actor kill -9 x{rounds} (one over shared memory, one over gRPC, at random): \
         0 rejected at the replay, the surviving actor pushed {survivor_pushed} transitions and \
         the learner trained through every kill; restart to first delivery median {:?}, max \
         {:?}; the killed actors' unsent buffers held about {in_flight} transitions (not \
         durable by design); the replay took {shm} over shm and {grpc} over gRPC",
        median(recoveries.clone()),
        recoveries.iter().max().copied().unwrap_or_default(),
    );
}

/// A tmpfs of `bytes` mounted on a new temporary folder, unmounted on
/// drop; `None` (the test says why it skips) where mounting is not
/// allowed, unless CROSSROADS_REQUIRE_MOUNT=1 (as `make test` sets when it
/// runs as root).
struct SmallDisk {
    dir: tempfile::TempDir,
}

impl SmallDisk {
    fn mount(bytes: u64) -> Option<Self> {
        let dir = tempfile::tempdir().expect("temp dir");
        let out = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={bytes}"), "tmpfs"])
            .arg(dir.path())
            .output();
        match out {
            Ok(o) if o.status.success() => Some(Self { dir }),
            other => {
                let why = match other {
                    Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_owned(),
                    Err(e) => e.to_string(),
                };
                gates::skip_unless_required(
                    Need::Mount,
                    &format!("cannot mount a tmpfs here ({why}); run as root"),
                );
                None
            }
        }
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg(self.dir.path())
            .status();
    }
}

/// The value of metric `name` on the line that also contains `label`.
fn metric(registry: &prometheus::Registry, name: &str, label: &str) -> f64 {
    let text = crossroads_common::metrics::render(registry);
    text.lines()
        .find(|l| l.starts_with(name) && l.contains(label))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {name} with {label} in\n{text}"))
}

#[test]
#[ignore = "needs root to mount a tmpfs (make test runs it)"]
fn a_full_replay_disk_fails_writes_clearly_corrupts_nothing_and_keeps_serving() {
    let Some(disk) = SmallDisk::mount(1 << 20) else {
        return;
    };
    let rt = runtime();
    // Clients connect lazily, on this runtime.
    let _enter = rt.enter();
    let mut config = crossroads_config::Config::default();
    config.replay.listen = "127.0.0.1:0".parse().expect("addr");
    config.replay.table = "faults".to_owned();
    config.replay.capacity = 100_000;
    config.replay.min_size_to_sample = 1;
    config.replay.shm_ingest = false;
    config.replay.snapshot_interval_secs = 0;
    config.replay.snapshot_dir = Some(disk.path().join("replay"));
    let registry = crossroads_common::metrics::registry("replay").expect("registry");
    let shutdown = crossroads_common::Shutdown::new();
    let server = rt
        .block_on(crossroads_replay::start(
            &config,
            Some(&registry),
            shutdown.clone(),
        ))
        .expect("start");
    let addr = server.local_addr().to_string();
    let client = replay_client(&addr);
    // Leave the log a little room, then fill it.
    let filler = disk.path().join("filler");
    std::fs::write(&filler, vec![0u8; (1 << 20) - (64 << 10)]).expect("filler");
    let (mut acked, mut tag) = (Vec::new(), 1);
    let refusal = loop {
        match rt.block_on(client.insert(tagged(tag))) {
            Ok(_) => acked.push(tag),
            Err(e) => break e,
        }
        tag += 1;
        assert!(tag < 10_000, "the disk never filled");
    };
    assert_eq!(refusal.code(), Some(tonic::Code::Unavailable), "{refusal}");
    let text = refusal.to_string();
    assert!(
        text.contains("No space left on device") && text.contains("write-ahead log"),
        "names the problem: {text}"
    );
    assert!(metric(&registry, "crossroads_replay_wal_errors_total", "") >= 1.0);
    assert!(
        metric(
            &registry,
            "crossroads_replay_rejections_total",
            "unavailable"
        ) >= 1.0
    );
    // Within the second after, an insert is refused before it touches the
    // table.
    let size = rt.block_on(client.info()).expect("info").size;
    let again = rt
        .block_on(client.insert(tagged(tag + 1)))
        .expect_err("refused");
    assert!(again.to_string().contains("nothing stored"), "{again}");
    assert_eq!(rt.block_on(client.info()).expect("info").size, size);
    // A snapshot fails with a clear error and a metric; the server still
    // serves samples.
    let failed = rt.block_on(client.snapshot()).expect_err("no room");
    assert!(
        failed.to_string().contains("No space left on device"),
        "{failed}"
    );
    assert!(metric(&registry, "crossroads_replay_snapshots_total", "\"error\"") >= 1.0);
    let sample = rt
        .block_on(client.sample(8, 0.5, Duration::from_secs(1)))
        .expect("still serving");
    assert_eq!(sample.keys.len(), 8);
    // What was written is whole: every segment reads to its end.
    let wal_dir = disk.path().join("replay").join("wal");
    for entry in std::fs::read_dir(&wal_dir).expect("wal folder") {
        let bytes = std::fs::read(entry.expect("entry").path()).expect("read");
        let decoded = crossroads_replay::wal::decode_segment(&bytes).expect("a whole header");
        assert_eq!(decoded.torn, None, "cut back to its last whole record");
    }
    // Room again: inserts resume (after the second of refusal), and a
    // crash now loses nothing acknowledged.
    std::fs::remove_file(&filler).expect("free the disk");
    std::thread::sleep(Duration::from_millis(1100));
    for t in 20_000..20_005 {
        rt.block_on(client.insert(tagged(t)))
            .expect("inserts again");
        acked.push(t);
    }
    let crashed = tempfile::tempdir().expect("temp dir");
    crash_copy(&disk.path().join("replay"), crashed.path());
    shutdown.trigger();
    rt.block_on(server.join()).expect("clean stop");
    let (replay, addr, _) = start_replay(crashed.path());
    let held = stored(&rt, &addr);
    let lost: Vec<_> = acked.iter().filter(|t| held.get(t) != Some(&10)).collect();
    assert!(lost.is_empty(), "acknowledged and lost: {lost:?}");
    replay.terminate();
    eprintln!(
        "faults: replay disk full: {} batches acknowledged before and after, 0 lost; \
         inserts refused with UNAVAILABLE naming the disk while full; samples served throughout",
        acked.len()
    );
}

/// A network namespace with a veth pair to this one: the host side is
/// `<prefix>.1`, the namespace side `<prefix>.2`. Deleted (with its link)
/// on drop.
struct Netns {
    name: String,
    prefix: String,
}

fn sh(program: &str, args: &[&str]) -> Result<(), String> {
    let out = std::process::Command::new(program)
        .args(args)
        .output()
        .map_err(|e| format!("{program}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "{program} {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl Netns {
    /// `None` (the test says why it skips) where namespaces cannot be made,
    /// unless CROSSROADS_REQUIRE_MOUNT=1 (as `make test` sets as root).
    fn create() -> Option<Self> {
        let id = std::process::id();
        let ns = Self {
            name: format!("crf{id}"),
            prefix: format!("10.231.{}", id % 250 + 1),
        };
        let (host, inside) = (format!("crfh{id}"), format!("crfa{id}"));
        let made = (|| {
            sh("ip", &["netns", "add", &ns.name])?;
            sh(
                "ip",
                &[
                    "link", "add", &host, "type", "veth", "peer", "name", &inside,
                ],
            )?;
            sh("ip", &["link", "set", &inside, "netns", &ns.name])?;
            sh(
                "ip",
                &["addr", "add", &format!("{}.1/24", ns.prefix), "dev", &host],
            )?;
            sh("ip", &["link", "set", &host, "up"])?;
            let exec = |args: &[&str]| {
                let mut all = vec!["netns", "exec", &ns.name];
                all.extend_from_slice(args);
                sh("ip", &all)
            };
            exec(&[
                "ip",
                "addr",
                "add",
                &format!("{}.2/24", ns.prefix),
                "dev",
                &inside,
            ])?;
            exec(&["ip", "link", "set", &inside, "up"])?;
            exec(&["ip", "link", "set", "lo", "up"])
        })();
        match made {
            Ok(()) => Some(ns),
            Err(why) => {
                gates::skip_unless_required(
                    Need::Mount,
                    &format!("cannot make a network namespace here ({why}); run as root"),
                );
                None
            }
        }
    }

    /// Drops (or, `cut = false`, lets through again) TCP from the namespace
    /// to the host's `port`, both ways.
    fn partition(&self, port: u16, cut: bool) {
        let op = if cut { "-A" } else { "-D" };
        let host = format!("{}.1", self.prefix);
        let port = port.to_string();
        for rule in [
            ["OUTPUT", "-d", host.as_str(), "--dport", port.as_str()],
            ["INPUT", "-s", host.as_str(), "--sport", port.as_str()],
        ] {
            sh(
                "ip",
                &[
                    "netns", "exec", &self.name, "iptables", op, rule[0], rule[1], rule[2], "-p",
                    "tcp", rule[3], rule[4], "-j", "DROP",
                ],
            )
            .expect("iptables");
        }
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = sh("ip", &["netns", "del", &self.name]);
    }
}

/// The value of `name` (summed over labels) on the metrics page at `addr`.
fn scrape(addr: &str, name: &str) -> Option<f64> {
    scrape_where(addr, name, "")
}

/// The value of `name` summed over the series whose labels contain
/// `label` (`transport="shm"`).
fn scrape_where(addr: &str, name: &str, label: &str) -> Option<f64> {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(
        s,
        "GET /metrics HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    let mut text = String::new();
    s.read_to_string(&mut text).ok()?;
    let values: Vec<f64> = text
        .lines()
        .filter(|l| l.starts_with(name) && l[name.len()..].starts_with([' ', '{']))
        .filter(|l| l.contains(label))
        .filter_map(|l| l.rsplit(' ').next()?.parse().ok())
        .collect();
    (!values.is_empty()).then(|| values.iter().sum())
}

/// Polls `probe` every 200 ms until `done` holds of its value; returns how
/// long that took, or fails naming `what` after `limit`.
fn wait_until<T: std::fmt::Debug>(
    what: &str,
    limit: Duration,
    mut probe: impl FnMut() -> T,
    done: impl Fn(&T) -> bool,
) -> Duration {
    let start = Instant::now();
    loop {
        let v = probe();
        if done(&v) {
            return start.elapsed();
        }
        assert!(
            start.elapsed() < limit,
            "{what}: still {v:?} after {limit:?}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
#[ignore = "needs root for network namespaces (make test runs it)"]
fn partitions_of_an_actor_from_the_replay_and_the_learner_heal_without_restarts() {
    let Some(ns) = Netns::create() else {
        return;
    };
    let cut_for = Duration::from_secs(if long() { 40 } else { 12 });
    let rt = runtime();
    let _enter = rt.enter();
    let host = format!("{}.1", ns.prefix);
    let with_common = |extra: &[&str]| -> Vec<String> {
        SMALL_RUN
            .iter()
            .chain(extra)
            .map(|s| (*s).to_owned())
            .collect()
    };
    let port_of = |addr: &str| -> u16 {
        addr.rsplit(':')
            .next()
            .and_then(|p| p.parse().ok())
            .expect("a port")
    };
    let listen = format!("{host}:0");
    let replay = crate::crossroads().spawn_role(&with_common(&[
        "--set",
        "replay.min_size_to_sample=200",
        "replay",
        "--listen",
        &listen,
        "--no-shm",
        "--capacity",
        "50000",
        "--table",
        "faults",
    ]));
    let replay_addr = replay.addr("replay server listening");
    let replay_url = format!("http://{replay_addr}");
    let learner = crate::crossroads().spawn_role(&with_common(&[
        "learner",
        "--listen",
        &listen,
        "--no-shm",
        "--replay",
        &replay_url,
    ]));
    let learner_addr = learner.addr("learner listening");
    let learner_url = format!("http://{learner_addr}");
    let metrics = format!("{}.2:9464", ns.prefix);
    let metrics_addr = format!("telemetry.metrics_addr={metrics}");
    let mut actor = crate::crossroads()
        .under(&["ip", "netns", "exec", ns.name.as_str()])
        .spawn_role(&with_common(&[
            "--set",
            "telemetry.metrics=true",
            "--set",
            &metrics_addr,
            "--set",
            "transport.request_timeout_ms=3000",
            "--set",
            "transport.connect_timeout_ms=2000",
            "--set",
            "transport.max_backoff_ms=2000",
            "actor",
            "--transport",
            "grpc",
            "--weights",
            "grpc",
            "--index",
            "0",
            "--count",
            "1",
            "--envs",
            "4",
            "--replay",
            &replay_url,
            "--learner",
            &learner_url,
        ]));
    let (replay_port, learner_port) = (port_of(&replay_addr), port_of(&learner_addr));
    let pushed = || scrape(&metrics, "crossroads_actor_transitions_pushed_total").unwrap_or(0.0);
    let actor_version = || scrape(&metrics, "crossroads_actor_weights_version").unwrap_or(0.0);
    let learner_rpc = learner_client(&learner_addr);
    let learner_version = || {
        rt.block_on(learner_rpc.status())
            .map_or(0, |s| s.weights_version)
    };
    let stored = || {
        rt.block_on(replay_client(&replay_addr).info())
            .expect("the replay answers the host")
            .inserts_total
    };
    // Training runs: the actor pushes, the learner publishes, the actor
    // follows.
    wait_until("the actor pushing", Duration::from_secs(90), pushed, |p| {
        *p > 500.0
    });
    wait_until(
        "the actor on learned weights",
        Duration::from_secs(90),
        actor_version,
        |v| *v >= 2.0,
    );

    // Actor <-> replay cut: nothing reaches the table; the actor lives on.
    ns.partition(replay_port, true);
    std::thread::sleep(Duration::from_secs(3));
    let (stored_at_cut, pushed_at_cut) = (stored(), pushed());
    std::thread::sleep(cut_for);
    assert_eq!(stored(), stored_at_cut, "nothing crossed the cut");
    assert!(actor.is_running(), "the actor survived the cut");
    assert_eq!(pushed(), pushed_at_cut);
    ns.partition(replay_port, false);
    let replay_recovery = wait_until(
        "inserts after the replay cut healed",
        Duration::from_secs(60),
        stored,
        |s| *s > stored_at_cut,
    );
    let dropped = scrape(&metrics, "crossroads_actor_transitions_dropped_total").unwrap_or(0.0);

    // Actor <-> learner cut: the learner publishes on, the actor keeps
    // acting on the weights it has and catches up after.
    ns.partition(learner_port, true);
    std::thread::sleep(Duration::from_secs(3));
    let held = actor_version();
    let stored_during = stored();
    std::thread::sleep(cut_for);
    assert_eq!(actor_version(), held, "no weights crossed the cut");
    assert!(learner_version() as f64 > held, "the learner published on");
    assert!(
        stored() > stored_during,
        "the actor kept pushing to the replay"
    );
    let published = learner_version() as f64;
    ns.partition(learner_port, false);
    let learner_recovery = wait_until(
        "weights after the learner cut healed",
        Duration::from_secs(60),
        actor_version,
        |v| *v >= published,
    );
    assert!(actor.is_running(), "the actor survived both cuts");
    actor.terminate();
    learner.terminate();
    replay.terminate();
    eprintln!(
        "faults: an actor cut from the replay for {cut_for:?} then from the learner for {cut_for:?}, \
         no restart: inserts resumed {replay_recovery:?} after the first heal, weights caught up \
         {learner_recovery:?} after the second; the actor dropped {dropped} transitions it could \
         not deliver during the cut (counted by crossroads_actor_transitions_dropped_total)"
    );
}
