//! `crossroads bench actor`: transitions per second of one actor process,
//! inference included, for several environment counts M and three ways to
//! the replay: in-process (batches inserted into the table directly),
//! iceoryx2 shared memory and gRPC (both to a real replay server running
//! in this process, on loopback).
//!
//! An actor steps continuously; every `seconds` the transitions the replay
//! has stored since the last mark are counted, so a transport slower than
//! the actor shows as a lower rate (and as dropped batches once the push
//! buffer is full), not as a backlog that is never timed.

use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use crossroads_actor::{ActorMetrics, ActorParts, PushConfig, Pusher, hostname};
use crossroads_common::Shutdown;
use crossroads_config::{ActorTransport, Config};
use crossroads_learner::bench::median;
use crossroads_replay::{PreparedBatch, Table};
use serde::Serialize;

use super::{describe_network, load_average};

/// What to measure.
#[derive(Debug, Clone)]
pub struct ActorBenchOptions {
    /// Environment counts M.
    pub envs: Vec<usize>,
    /// Transports: `inproc`, `shm`, `grpc`.
    pub transports: Vec<String>,
    /// Timed rounds per cell; the median is reported.
    pub rounds: usize,
    /// Seconds per round.
    pub seconds: f64,
    /// Seconds of warm-up before the first round.
    pub warmup: f64,
    /// Print JSON.
    pub json: bool,
}

/// One cell of the table.
#[derive(Debug, Clone, Serialize)]
struct Cell {
    transport: String,
    envs: usize,
    transitions_per_sec: f64,
    env_steps_per_sec: f64,
    forward_passes_per_sec: f64,
    inference_fraction: f64,
    /// Lanes the environments act in (2: pipelined).
    lanes: usize,
    /// The forward pass runs in plain Rust (`NativeMlp`), not libtorch.
    native: bool,
    dropped: u64,
    rounds: Vec<f64>,
}

/// Where the acting thread puts its batches.
enum Sink {
    Table(Arc<Table>),
    Pusher(Pusher),
}

/// Measures and prints.
pub fn run(config: &Config, o: &ActorBenchOptions) -> anyhow::Result<ExitCode> {
    for t in &o.transports {
        anyhow::ensure!(
            matches!(t.as_str(), "inproc" | "shm" | "grpc"),
            "unknown transport {t:?}: choose from inproc, shm, grpc"
        );
    }
    anyhow::ensure!(
        o.envs.iter().all(|&m| (1..=4096).contains(&m)),
        "--envs must each be between 1 and 4096"
    );
    if let Some(n) = config.runtime.torch_threads() {
        tch::set_num_threads(n as i32);
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let mut cells = Vec::new();
    for transport in &o.transports {
        for &m in &o.envs {
            let cell = runtime
                .block_on(measure(config, o, transport, m))
                .with_context(|| format!("{transport}, M = {m}"))?;
            if !o.json {
                eprintln!(
                    "  {transport:<7} M = {m:<3} {:>9.0} transitions/s",
                    cell.transitions_per_sec
                );
            }
            cells.push(cell);
        }
    }
    let spec = crossroads_model::network_spec(&config.sim, &config.learner)?;
    let network = describe_network(&spec);
    let load = load_average();
    let forward = cells.first().map_or("", |c| {
        if c.native {
            "plain-Rust forward pass"
        } else {
            "libtorch forward pass"
        }
    });
    let lanes = cells.iter().map(|c| c.lanes).max().unwrap_or(1);
    if o.json {
        println!(
            "{}",
            serde_json::json!({
                "scenario": config.sim.scenario,
                "action_set": config.sim.action_set,
                "network": network,
                "batch_size": config.actor.batch_size,
                "n_step": config.actor.n_step,
                "rayon_threads": rayon::current_num_threads(),
                "torch_threads": tch::get_num_threads(),
                "rounds": o.rounds,
                "seconds": o.seconds,
                "load_average": load,
                "host": hostname(),
                "results": cells,
            })
        );
    } else {
        println!(
            "actor throughput on {} ({} actions), {network} ({forward}), batches of {}, {}-step, {}; rayon {} threads, libtorch {}; median of {} rounds of {:.1} s (load average {load})",
            config.sim.scenario,
            config.sim.action_set,
            config.actor.batch_size,
            config.actor.n_step,
            if lanes > 1 {
                "two lanes (actor.pipeline)"
            } else {
                "one lane"
            },
            rayon::current_num_threads(),
            tch::get_num_threads(),
            o.rounds,
            o.seconds,
        );
        println!(
            "transport    M  transitions/s  env steps/s  forward passes/s  inference  dropped"
        );
        for c in &cells {
            println!(
                "{:<9} {:>4}  {:>13.0}  {:>11.0}  {:>16.0}  {:>8.0}%  {:>7}",
                c.transport,
                c.envs,
                c.transitions_per_sec,
                c.env_steps_per_sec,
                c.forward_passes_per_sec,
                100.0 * c.inference_fraction,
                c.dropped
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

async fn measure(
    config: &Config,
    o: &ActorBenchOptions,
    transport: &str,
    m: usize,
) -> anyhow::Result<Cell> {
    let mut c = config.clone();
    c.replay.listen = ([127, 0, 0, 1], 0).into();
    c.replay.snapshot_dir = None;
    c.replay.samples_per_insert = 0.0;
    c.replay.capacity = c.replay.capacity.max(1 << 20);
    c.replay.shm_ingest = transport == "shm";
    c.transport.shm_prefix = format!("crossroads-bench/actor-{}-{m}", std::process::id());
    c.actor.envs = m;
    let servers = Shutdown::new();
    let server = crossroads_replay::start(&c, None, servers.clone())
        .await
        .context("starting a replay server")?;
    c.transport.replay_endpoint = format!("{}://{}", c.transport.tls.scheme(), server.local_addr());
    let table = server
        .table(&c.replay.table)
        .context("the replay server has no table")?;

    // The actor a process runs (its live network, never sent newer
    // weights here, times its forward passes in the metrics).
    let metrics = ActorMetrics::new(None, &c.sim.scenario)?;
    let ActorParts {
        mut actor,
        mut network,
        ..
    } = ActorParts::new(&c, 0, metrics.clone())?;
    let (lanes, native) = (actor.lanes(), network.is_native());
    let sink = match transport {
        "inproc" => Sink::Table(Arc::clone(&table)),
        kind => {
            c.actor.transport = if kind == "shm" {
                ActorTransport::Shm
            } else {
                ActorTransport::Grpc
            };
            Sink::Pusher(Pusher::start(
                &PushConfig::from_config(&c),
                metrics.clone(),
                &servers,
            )?)
        }
    };

    let stop = Shutdown::new();
    let acting_stop = stop.clone();
    let torch_threads = config.runtime.torch_threads();
    let acting = tokio::task::spawn_blocking(move || -> anyhow::Result<Sink> {
        // As the actor process does: per thread, on the acting one.
        if let Some(n) = torch_threads {
            tch::set_num_threads(n as i32);
        }
        while !acting_stop.is_triggered() {
            actor.step(&mut network)?;
            while let Some(batch) = actor.take_batch() {
                match &sink {
                    Sink::Table(t) => {
                        t.insert_now(&PreparedBatch::try_from(batch)?)?;
                    }
                    Sink::Pusher(p) => p.push(batch),
                }
            }
        }
        Ok(sink)
    });

    tokio::time::sleep(Duration::from_secs_f64(o.warmup.max(0.0))).await;
    let round = Duration::from_secs_f64(o.seconds.max(0.1));
    let mut rates = Vec::new();
    let mut steps = Vec::new();
    let mut passes = Vec::new();
    let mut inference = Vec::new();
    let dropped0 = metrics.dropped_total("buffer_full");
    for _ in 0..o.rounds.max(1) {
        let passes_and_busy = || {
            (
                metrics.forward_passes_total(),
                metrics.inference_seconds_total(),
            )
        };
        let (t0, i0, s0, (c0, b0)) = (
            Instant::now(),
            table.stats().info.inserts_total,
            metrics.env_steps_total(),
            passes_and_busy(),
        );
        tokio::time::sleep(round).await;
        if acting.is_finished() {
            break;
        }
        let dt = t0.elapsed().as_secs_f64();
        let (c1, b1) = passes_and_busy();
        rates.push((table.stats().info.inserts_total - i0) as f64 / dt);
        steps.push((metrics.env_steps_total() - s0) as f64 / dt);
        passes.push((c1 - c0) as f64 / dt);
        inference.push((b1 - b0) / dt);
    }
    stop.trigger();
    let sink = acting.await.context("the acting thread")??;
    anyhow::ensure!(!rates.is_empty(), "the acting thread stopped early");
    if let Sink::Pusher(p) = sink {
        p.close(Duration::from_secs(5)).await;
    }
    servers.trigger();
    server.join().await.context("replay server")?;
    Ok(Cell {
        transport: transport.to_owned(),
        envs: m,
        transitions_per_sec: median(&rates),
        env_steps_per_sec: median(&steps),
        forward_passes_per_sec: median(&passes),
        inference_fraction: median(&inference),
        lanes,
        native,
        dropped: metrics.dropped_total("buffer_full") - dropped0,
        rounds: rates,
    })
}
