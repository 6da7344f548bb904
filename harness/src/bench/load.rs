//! `crossroads bench load`: one replay server under many actors' insert
//! streams (gRPC and iceoryx2), with the write-ahead log off and on, and
//! one learner under many weight subscribers of which one never reads.
//!
//! Everything runs in this process on loopback: the server, the learner
//! and the clients, each client with its own connection as separate actor
//! processes would have. Memory is this process's resident set, sampled
//! every 250 ms; the table's own bytes are what it reports.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use crossroads_common::Shutdown;
use crossroads_config::Config;
use crossroads_replay::bench::SyntheticEpisodes;
use crossroads_transport::grpc::ReplayClient;
use crossroads_transport::learner_client::LearnerClient;
use crossroads_transport::security::ClientSecurity;
use crossroads_transport::shm::ShmBatchPublisher;
use crossroads_types::{TransitionBatch, ValidBatch};
use serde::Serialize;

/// What to run.
#[derive(Debug, Clone)]
pub(super) struct LoadBenchOptions {
    pub streams: usize,
    pub shm: usize,
    pub seconds: f64,
    pub capacity: u64,
    pub batch: usize,
    pub wal: Vec<bool>,
    pub subscribers: usize,
    pub json: bool,
}

/// One replay run's figures.
#[derive(Debug, Serialize)]
struct ReplayLoad {
    wal: bool,
    grpc_streams: usize,
    shm_publishers: usize,
    seconds: f64,
    transitions_per_s: f64,
    grpc_batches: u64,
    shm_batches: u64,
    ack_p50_ms: f64,
    ack_p99_ms: f64,
    shm_ack_p50_ms: f64,
    shm_ack_p99_ms: f64,
    refused: u64,
    capacity: u64,
    size: u64,
    table_mib: f64,
    bytes_per_transition: f64,
    rss_before_mib: f64,
    rss_peak_mib: f64,
    rss_end_mib: f64,
    /// Peak minus the start and the table's own bytes.
    overhead_mib: f64,
}

/// The weights run's figures.
#[derive(Debug, Serialize)]
struct WeightsLoad {
    subscribers: usize,
    seconds: f64,
    weights_mib: f64,
    versions_published: u64,
    /// Versions the slowest live subscriber got, of those published while
    /// it listened.
    min_versions_received: u64,
    /// Versions no live subscriber missed: published minus the largest
    /// count of gaps any one of them saw.
    max_gaps: u64,
    rss_before_mib: f64,
    rss_peak_mib: f64,
    rss_end_mib: f64,
}

#[derive(Debug, Serialize)]
struct Report {
    machine: String,
    replay: Vec<ReplayLoad>,
    weights: Option<WeightsLoad>,
}

/// Runs the measurements and prints them.
pub(super) fn run(config: &Config, o: &LoadBenchOptions) -> anyhow::Result<ExitCode> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let mut report = Report {
        machine: crate::train::session::machine(),
        replay: Vec::new(),
        weights: None,
    };
    for wal in &o.wal {
        if !o.json {
            eprintln!(
                "load: {} gRPC streams and {} shared-memory publishers for {:.0} s, write-ahead log {}",
                o.streams,
                o.shm,
                o.seconds,
                if *wal { "on" } else { "off" }
            );
        }
        report
            .replay
            .push(runtime.block_on(replay_load(config, o, *wal))?);
    }
    if o.subscribers > 0 {
        if !o.json {
            eprintln!(
                "load: {} weight subscribers (one never reads) for {:.0} s",
                o.subscribers, o.seconds
            );
        }
        report.weights = Some(runtime.block_on(weights_load(config, o))?);
    }
    if o.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print(&report);
    }
    Ok(ExitCode::SUCCESS)
}

fn print(r: &Report) {
    println!("load on {}", r.machine);
    for l in &r.replay {
        println!(
            "replay, write-ahead log {}: {} gRPC streams + {} shm publishers, {:.0} s",
            if l.wal { "on" } else { "off" },
            l.grpc_streams,
            l.shm_publishers,
            l.seconds
        );
        println!(
            "  stored {:.0} transitions/s ({} gRPC and {} shm batches); refused {}",
            l.transitions_per_s, l.grpc_batches, l.shm_batches, l.refused
        );
        println!(
            "  ack latency gRPC p50 {:.2} ms, p99 {:.2} ms; shm p50 {:.2} ms, p99 {:.2} ms",
            l.ack_p50_ms, l.ack_p99_ms, l.shm_ack_p50_ms, l.shm_ack_p99_ms
        );
        println!(
            "  table {} of {} items, {:.1} MiB ({:.0} bytes per transition)",
            l.size, l.capacity, l.table_mib, l.bytes_per_transition
        );
        println!(
            "  resident memory: {:.0} MiB before, peak {:.0}, end {:.0}; peak - before - table = {:.0} MiB",
            l.rss_before_mib, l.rss_peak_mib, l.rss_end_mib, l.overhead_mib
        );
    }
    if let Some(w) = &r.weights {
        println!(
            "weights: {} subscribers, one stalled, {:.0} s, {:.2} MiB per version",
            w.subscribers, w.seconds, w.weights_mib
        );
        println!(
            "  {} versions published; the slowest live subscriber got {}, at most {} missed by any",
            w.versions_published, w.min_versions_received, w.max_gaps
        );
        println!(
            "  resident memory: {:.0} MiB before, peak {:.0}, end {:.0}",
            w.rss_before_mib, w.rss_peak_mib, w.rss_end_mib
        );
    }
}

/// This process's resident set, MiB.
fn rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Samples [`rss_mib`] every 250 ms until dropped; reports the peak.
struct RssSampler {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<f64>>,
}

impl RssSampler {
    fn start() -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut peak = rss_mib();
            while !flag.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(250));
                peak = peak.max(rss_mib());
            }
            peak
        });
        Self {
            stop,
            thread: Some(thread),
        }
    }

    fn peak(mut self) -> f64 {
        self.stop.store(true, Ordering::Relaxed);
        self.thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_else(rss_mib)
    }
}

fn quantile_ms(sorted_us: &[u32], q: f64) -> f64 {
    if sorted_us.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted_us.len() - 1) as f64 * q).round() as usize;
    f64::from(sorted_us[i]) / 1000.0
}

/// The run's config without TLS and tokens: the load is measured on plain
/// loopback gRPC.
fn plain(config: &Config) -> Config {
    let mut c = config.clone();
    c.transport.tls = Default::default();
    c.transport.auth = Default::default();
    c
}

/// Realistic batches (synthetic TTG episodes), made before the clock runs.
fn batches(n: usize, size: usize) -> Vec<TransitionBatch> {
    let mut episodes = SyntheticEpisodes::new(7);
    (0..n).map(|_| episodes.batch(size)).collect()
}

async fn replay_load(
    config: &Config,
    o: &LoadBenchOptions,
    wal: bool,
) -> anyhow::Result<ReplayLoad> {
    let dir = tempfile::tempdir().context("a temporary folder for the log")?;
    let mut c = plain(config);
    c.replay.listen = ([127, 0, 0, 1], 0).into();
    c.replay.capacity = o.capacity;
    c.replay.samples_per_insert = 0.0;
    c.replay.max_batch_transitions = c.replay.max_batch_transitions.max(o.batch as u32);
    c.replay.snapshot_dir = wal.then(|| dir.path().to_path_buf());
    c.replay.snapshot_interval_secs = 0;
    c.replay.wal = wal;
    c.replay.shm_ingest = o.shm > 0;
    c.transport.shm_prefix = format!("crossroads-load-{}-{}", std::process::id(), wal);
    let table = c.replay.table.clone();
    let rss_before = rss_mib();
    let sampler = RssSampler::start();
    let shutdown = Shutdown::new();
    let server = crossroads_replay::start(&c, None, shutdown.clone())
        .await
        .context("starting the replay server")?;
    c.transport.replay_endpoint = format!("http://{}", server.local_addr());
    let pool = Arc::new(batches(64, o.batch));
    let deadline = Instant::now() + Duration::from_secs_f64(o.seconds);

    let mut grpc = Vec::new();
    for s in 0..o.streams {
        let client = ReplayClient::new(&c.transport, &table)?;
        let pool = pool.clone();
        grpc.push(tokio::spawn(async move {
            let mut latencies = Vec::new();
            let (mut refused, mut i) = (0u64, s);
            let mut stream = client.insert_stream(1).await?;
            while Instant::now() < deadline {
                let sent = Instant::now();
                stream.send(pool[i % pool.len()].clone()).await?;
                match stream.next_ack().await {
                    Ok(_) => latencies.push(sent.elapsed().as_micros() as u32),
                    Err(_) => {
                        refused += 1;
                        stream = client.insert_stream(1).await?;
                    }
                }
                i += 1;
            }
            stream.finish().await?;
            anyhow::Ok((latencies, refused))
        }));
    }
    let mut shm = Vec::new();
    for p in 0..o.shm {
        let transport = c.transport.clone();
        let (table, pool) = (table.clone(), pool.clone());
        shm.push(std::thread::spawn(move || {
            shm_publisher(&transport, &table, &pool, p, deadline)
        }));
    }

    let (mut latencies, mut refused, mut grpc_batches) = (Vec::new(), 0, 0);
    for task in grpc {
        let (l, r) = task.await.context("a gRPC stream task")??;
        grpc_batches += l.len() as u64;
        latencies.extend(l);
        refused += r;
    }
    let (mut shm_latencies, mut shm_batches) = (Vec::new(), 0);
    for thread in shm {
        let (l, r) = thread
            .join()
            .map_err(|_| anyhow::anyhow!("a shared-memory publisher panicked"))??;
        shm_batches += l.len() as u64;
        shm_latencies.extend(l);
        refused += r;
    }
    latencies.sort_unstable();
    shm_latencies.sort_unstable();
    let stats = server.table(&table).context("the table")?.stats();
    let rss_end = rss_mib();
    shutdown.trigger();
    server.join().await.context("stopping the replay server")?;
    let rss_peak = sampler.peak();
    let table_mib = stats.info.bytes_stored as f64 / (1 << 20) as f64;
    Ok(ReplayLoad {
        wal,
        grpc_streams: o.streams,
        shm_publishers: o.shm,
        seconds: o.seconds,
        transitions_per_s: ((grpc_batches + shm_batches) as f64 * o.batch as f64) / o.seconds,
        grpc_batches,
        shm_batches,
        ack_p50_ms: quantile_ms(&latencies, 0.5),
        ack_p99_ms: quantile_ms(&latencies, 0.99),
        shm_ack_p50_ms: quantile_ms(&shm_latencies, 0.5),
        shm_ack_p99_ms: quantile_ms(&shm_latencies, 0.99),
        refused,
        capacity: o.capacity,
        size: stats.info.size,
        table_mib,
        bytes_per_transition: stats.info.bytes_stored as f64 / stats.info.size.max(1) as f64,
        rss_before_mib: rss_before,
        rss_peak_mib: rss_peak,
        rss_end_mib: rss_end,
        overhead_mib: rss_peak - rss_before - table_mib,
    })
}

/// One shared-memory publisher: at most four batches unacknowledged, each
/// acknowledgement's latency recorded.
fn shm_publisher(
    transport: &crossroads_config::TransportConfig,
    table: &str,
    pool: &[TransitionBatch],
    first: usize,
    deadline: Instant,
) -> anyhow::Result<(Vec<u32>, u64)> {
    let mut publisher = ShmBatchPublisher::new(transport, table)?;
    let valid: Vec<ValidBatch> = pool
        .iter()
        .map(|b| ValidBatch::new(b.clone()))
        .collect::<Result<_, _>>()?;
    let mut sent_at = std::collections::HashMap::new();
    let (mut latencies, mut refused, mut id) = (Vec::new(), 0u64, 0u64);
    let mut record = |acks: Vec<crossroads_transport::shm::ShmAck>,
                      sent_at: &mut std::collections::HashMap<u64, Instant>| {
        for ack in acks {
            if let Some(t) = sent_at.remove(&ack.batch_id) {
                match ack.outcome {
                    Ok(_) => latencies.push(t.elapsed().as_micros() as u32),
                    Err(_) => refused += 1,
                }
            }
        }
    };
    while Instant::now() < deadline {
        if publisher.in_flight().count() >= 4 {
            let acks = publisher.poll_acks()?;
            if acks.is_empty() {
                std::thread::sleep(Duration::from_micros(50));
            }
            record(acks, &mut sent_at);
            continue;
        }
        sent_at.insert(id, Instant::now());
        publisher.send(id, &valid[(first + id as usize) % valid.len()])?;
        id += 1;
        let acks = publisher.poll_acks()?;
        record(acks, &mut sent_at);
    }
    let acks = publisher.flush(Duration::from_secs(10))?;
    record(acks, &mut sent_at);
    Ok((latencies, refused))
}

async fn weights_load(config: &Config, o: &LoadBenchOptions) -> anyhow::Result<WeightsLoad> {
    let mut c = plain(config);
    c.replay.listen = ([127, 0, 0, 1], 0).into();
    c.replay.snapshot_dir = None;
    c.replay.shm_ingest = false;
    c.replay.samples_per_insert = 0.0;
    c.replay.min_size_to_sample = 1;
    let shutdown = Shutdown::new();
    let replay = crossroads_replay::start(&c, None, shutdown.clone())
        .await
        .context("starting the replay server")?;
    c.transport.replay_endpoint = format!("http://{}", replay.local_addr());
    let spec = crossroads_learner::TrainerConfig::from_config(&c.sim, &c.learner)?.spec;
    let client = ReplayClient::new(&c.transport, &c.replay.table)?;
    crossroads_learner::bench::fill_replay(&client, &spec, 2_000).await?;
    c.learner.listen = ([127, 0, 0, 1], 0).into();
    c.learner.checkpoint_dir = None;
    c.learner.shm_publish = false;
    c.learner.max_updates = 0;
    let rss_before = rss_mib();
    let sampler = RssSampler::start();
    let learner = crossroads_learner::start(&c, None, shutdown.clone())
        .await
        .context("starting the learner")?;
    let url = format!("http://{}", learner.local_addr());
    let deadline = Instant::now() + Duration::from_secs_f64(o.seconds);
    // The stalled subscriber: subscribed, never reads.
    let stalled = LearnerClient::new(&url, &ClientSecurity::none(), Duration::from_secs(30))?;
    let _stalled_stream = stalled.subscribe_weights(0).await?;
    let mut live = Vec::new();
    for _ in 1..o.subscribers {
        let client = LearnerClient::new(&url, &ClientSecurity::none(), Duration::from_secs(30))?;
        live.push(tokio::spawn(async move {
            let mut stream = client.subscribe_weights(0).await?;
            let (mut first, mut last, mut got, mut bytes) = (None, 0u64, 0u64, 0usize);
            while Instant::now() < deadline {
                match tokio::time::timeout_at(deadline.into(), stream.next()).await {
                    Ok(Ok(Some(w))) => {
                        first.get_or_insert(w.version);
                        last = w.version;
                        got += 1;
                        bytes = w.safetensors.len();
                    }
                    Ok(Ok(None)) => break,
                    Ok(Err(e)) => return Err(anyhow::Error::from(e)),
                    Err(_) => break,
                }
            }
            anyhow::Ok((first.unwrap_or(last), last, got, bytes))
        }));
    }
    let (mut min_got, mut max_gaps, mut bytes) = (u64::MAX, 0u64, 0usize);
    for task in live {
        let (first, last, got, b) = task.await.context("a subscriber task")??;
        min_got = min_got.min(got);
        max_gaps = max_gaps.max((last - first + 1).saturating_sub(got));
        bytes = bytes.max(b);
    }
    let published = LearnerClient::new(&url, &ClientSecurity::none(), Duration::from_secs(30))?
        .status()
        .await?
        .weights_version;
    let rss_end = rss_mib();
    shutdown.trigger();
    learner.join().await.context("stopping the learner")?;
    replay.join().await.context("stopping the replay server")?;
    Ok(WeightsLoad {
        subscribers: o.subscribers,
        seconds: o.seconds,
        weights_mib: bytes as f64 / (1 << 20) as f64,
        versions_published: published,
        min_versions_received: if min_got == u64::MAX { 0 } else { min_got },
        max_gaps,
        rss_before_mib: rss_before,
        rss_peak_mib: sampler.peak(),
        rss_end_mib: rss_end,
    })
}
