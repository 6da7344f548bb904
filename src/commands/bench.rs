//! `crossroads bench`: throughput and memory measured on this machine.
//!
//! `bench sim` and `bench replay` are here; `bench learner` (with the
//! PyTorch twin `scripts/bench_learner_torch.py`), `bench actor`, `bench
//! load` and `bench time-to-target` have a module each under `bench/`.

use std::process::ExitCode;
use std::time::Duration;

use crossroads_config::Config;
use crossroads_sim::bench_builtin;

use crate::cli::{BenchArgs, BenchTarget, GlobalArgs};

mod actor;
mod learner;
mod load;
mod target;

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
            &target::Options {
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
            &learner::Options {
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
            &actor::Options {
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
            &load::Options {
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
pub(crate) fn describe_network(spec: &crossroads_model::NetworkSpec) -> String {
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
