//! `crossroads bench`: throughput and memory measured on this machine.
//!
//! `bench sim` and `bench replay` are here; `bench learner` (with the
//! PyTorch twin `scripts/bench_learner_torch.py`), `bench actor`, `bench
//! load` and `bench time-to-target` have a module each under `bench/`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Args, Subcommand};
use crossroads_config::Config;
use crossroads_sim::bench_builtin;

use crate::global::GlobalArgs;

mod actor;
mod learner;
mod load;
mod target;

/// `crossroads bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub target: BenchTarget,
}

#[derive(Debug, Subcommand)]
pub enum BenchTarget {
    /// Simulator: TTG decisions/s with observations and traffic steps/s per
    /// core, for each built-in scenario.
    Sim {
        /// Least time per measurement, in seconds.
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Actor: transitions/s of one actor process, inference included, for
    /// each environment count M and each way to the replay.
    ///
    /// `inproc` inserts batches into the table directly; `shm` and `grpc`
    /// push them to a real replay server in this process over iceoryx2 and
    /// loopback gRPC. Counts what the replay stored per second (medians of
    /// the rounds), with env steps/s, forward passes/s and the share of
    /// time in inference. Scenario, action set, batch size and network come
    /// from the [actor] and [learner] sections (--set to change them).
    Actor {
        /// Environment counts M, comma-separated.
        #[arg(long, default_value = "1,8,32,64", value_delimiter = ',')]
        envs: Vec<usize>,
        /// Ways to the replay, comma-separated: inproc, shm, grpc.
        #[arg(
            long = "transport",
            default_value = "inproc,shm,grpc",
            value_delimiter = ','
        )]
        transports: Vec<String>,
        /// Timed rounds per cell; the median is reported.
        #[arg(long, default_value_t = 5)]
        rounds: usize,
        /// Seconds per round.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
        /// Seconds of acting before the first round.
        #[arg(long, default_value_t = 1.0)]
        warmup: f64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Load: one replay server under many actors' streams, and one learner
    /// under many weight subscribers with one stalled.
    ///
    /// Starts a replay server in this process and pushes synthetic TTG
    /// batches at it from --streams gRPC streams (each its own connection)
    /// and --shm iceoryx2 publishers for --seconds, with the write-ahead
    /// log off and on; prints transitions/s stored, ack latency p50/p99,
    /// the table's bytes and the resident memory (peak against the table's
    /// bytes). Then a learner (the run's network) trains on a filled replay
    /// while --subscribers subscribe to its weights, one of them never
    /// reading: prints the versions published and received by the slowest
    /// live subscriber, and the memory.
    Load {
        /// Concurrent gRPC insert streams.
        #[arg(long, default_value_t = 64)]
        streams: usize,
        /// Concurrent shared-memory publishers (at most transport.shm_max_publishers).
        #[arg(long, default_value_t = 8)]
        shm: usize,
        /// Seconds per measurement.
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
        /// Table capacity, items (the run exceeds it, so eviction is timed too).
        #[arg(long, default_value_t = 200_000)]
        capacity: u64,
        /// Transitions per batch.
        #[arg(long, default_value_t = 32)]
        batch: usize,
        /// Write-ahead log: off, on, or both (one run each).
        #[arg(long, default_value = "both", value_parser = ["off", "on", "both"])]
        wal: String,
        /// Weight subscribers on the learner (0 skips that part).
        #[arg(long, default_value_t = 64)]
        subscribers: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Replay table: bytes per transition, inserts/s, samples/s.
    ///
    /// Fills a table with synthetic TTG episodes (3-8 cars per grid), then
    /// times rounds of inserts (batches of 64) and samples (batches of 256)
    /// and prints the medians.
    Replay {
        /// Table capacity, filled before timing.
        #[arg(long, default_value_t = 262_144)]
        capacity: usize,
        /// Timed rounds; the median is reported.
        #[arg(long, default_value_t = 11)]
        rounds: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time to target: `crossroads train` of a built-in experiment from
    /// each seed (actor.seed and learner.seed), stopping at the
    /// experiment's target ([train] target_*); prints the wall time, env
    /// steps and updates to the confirmed target per seed and their
    /// medians, with the machine. --set applies to every training.
    TimeToTarget {
        /// Training seeds, comma-separated.
        #[arg(long, default_value = "1,2,3", value_delimiter = ',')]
        seeds: Vec<u64>,
        /// Give up on a seed after this many minutes (it counts as not
        /// reached).
        #[arg(long, default_value_t = 15.0)]
        minutes: f64,
        /// Keep the run folders here (default: a temporary folder, removed
        /// after).
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Learner: updates/s of the default network at each batch size on
    /// in-memory batches, then fed by a replay server over loopback gRPC
    /// (with the fraction of time spent waiting for samples), and the same
    /// network and optimizer in PyTorch for comparison.
    Learner {
        /// Batch sizes, comma-separated.
        #[arg(long, default_value = "64,256", value_delimiter = ',')]
        batch: Vec<u32>,
        /// libtorch (and PyTorch) intra-op threads [default:
        /// runtime.torch_threads, 1].
        #[arg(long)]
        threads: Option<usize>,
        /// Timed rounds per measurement; the median is reported.
        #[arg(long, default_value_t = 5)]
        rounds: usize,
        /// Seconds per round.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
        /// Updates of the gRPC-fed run per batch size.
        #[arg(long, default_value_t = 300)]
        fed_updates: u64,
        /// Python with torch for the comparison [default: $CROSSROADS_PYTHON,
        /// then .venv/bin/python3, then python3].
        #[arg(long)]
        python: Option<PathBuf>,
        /// Skip the PyTorch comparison.
        #[arg(long)]
        no_pytorch: bool,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

/// Runs the chosen measurement and prints its figures.
pub fn run(global: &GlobalArgs, config: &Config, args: &BenchArgs) -> anyhow::Result<ExitCode> {
    match &args.target {
        BenchTarget::TimeToTarget {
            seeds,
            minutes,
            out,
            json,
        } => target::run(
            global,
            &target::TimeToTargetOptions {
                seeds: seeds.clone(),
                minutes: *minutes,
                out: out.clone(),
                json: *json,
            },
        ),
        BenchTarget::Learner {
            batch,
            threads,
            rounds,
            seconds,
            fed_updates,
            python,
            no_pytorch,
            json,
        } => learner::run(
            config,
            &learner::LearnerBenchOptions {
                batches: batch.clone(),
                threads: threads
                    .or(config.runtime.learner_torch_threads())
                    .unwrap_or(1),
                rounds: *rounds,
                seconds: *seconds,
                fed_updates: *fed_updates,
                python: python.clone(),
                pytorch: !*no_pytorch,
                json: *json,
            },
        ),
        BenchTarget::Actor {
            envs,
            transports,
            rounds,
            seconds,
            warmup,
            json,
        } => actor::run(
            config,
            &actor::ActorBenchOptions {
                envs: envs.clone(),
                transports: transports.clone(),
                rounds: *rounds,
                seconds: *seconds,
                warmup: *warmup,
                json: *json,
            },
        ),
        BenchTarget::Load {
            streams,
            shm,
            seconds,
            capacity,
            batch,
            wal,
            subscribers,
            json,
        } => load::run(
            config,
            &load::LoadBenchOptions {
                streams: *streams,
                shm: *shm,
                seconds: *seconds,
                capacity: *capacity,
                batch: *batch,
                wal: match wal.as_str() {
                    "on" => vec![true],
                    "off" => vec![false],
                    _ => vec![false, true],
                },
                subscribers: *subscribers,
                json: *json,
            },
        ),
        BenchTarget::Sim { seconds, json } => sim(*seconds, *json),
        BenchTarget::Replay {
            capacity,
            rounds,
            json,
        } => {
            replay(*capacity, *rounds, *json);
            Ok(ExitCode::SUCCESS)
        }
    }
}

fn sim(seconds: f64, json: bool) -> anyhow::Result<ExitCode> {
    let min = Duration::from_secs_f64(seconds.max(0.1));
    let figures = bench_builtin(min)?;
    if json {
        println!("{}", serde_json::to_string(&figures)?);
    } else {
        println!(
            "simulator throughput on one thread ({:.1} s per measurement)",
            min.as_secs_f64()
        );
        println!("scenario    TTG decisions/s (with observation)  traffic steps/s  mean cars");
        for f in &figures {
            println!(
                "{:<10}  {:>34.0}  {:>15.0}  {:>9.1}",
                f.scenario, f.decisions_per_s, f.steps_per_s, f.mean_cars
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn replay(capacity: usize, rounds: usize, json: bool) {
    let r = crossroads_replay::bench::run(capacity, rounds);
    if json {
        println!(
            "{{\"capacity\":{},\"bytes_per_transition\":{:.1},\"inserts_per_sec\":{:.0},\"samples_per_sec\":{:.0}}}",
            r.capacity, r.bytes_per_transition, r.inserts_per_sec, r.samples_per_sec
        );
    } else {
        println!(
            "replay table, {} synthetic TTG transitions (3-8 cars)",
            r.capacity
        );
        println!(
            "  bytes per stored transition   {:.1}",
            r.bytes_per_transition
        );
        println!("  inserts/s (median, batch 64)  {:.0}", r.inserts_per_sec);
        println!("  samples/s (median, batch 256) {:.0}", r.samples_per_sec);
    }
}

/// `dueling mlp 2344-256-256 -> 5`: a network in one line.
pub fn describe_network(spec: &crossroads_model::NetworkSpec) -> String {
    let hidden: Vec<String> = spec.hidden.iter().map(i64::to_string).collect();
    format!(
        "dueling {} {}-{} -> {}",
        spec.trunk.name(),
        spec.input_len(),
        hidden.join("-"),
        spec.num_actions
    )
}

/// The one-minute load average, to print beside figures measured on a
/// shared machine; empty when unknown.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_owned))
        .unwrap_or_default()
}
