//! `crossroads bench learner`: updates/s of the configured network (by
//! default the `[learner]` defaults: dueling MLP 2344-256-256 over the TTG
//! grid, RMSProp) in memory and fed over gRPC, and the same network and
//! optimizer in PyTorch, measured in the same run.

use std::path::PathBuf;
use std::process::{Command, ExitCode};
use std::time::Duration;

use anyhow::Context;
use crossroads_common::Shutdown;
use crossroads_config::Config;
use crossroads_learner::TrainerConfig;
use crossroads_learner::bench::{FedReport, fed, fill_replay, updates_per_second};
use crossroads_learner::optimizer::OptimizerConfig;
use crossroads_model::Precision;
use crossroads_transport::grpc::ReplayClient;
use serde_json::json;

/// What to measure.
#[derive(Debug, Clone)]
pub struct LearnerBenchOptions {
    pub batches: Vec<u32>,
    pub threads: usize,
    pub rounds: usize,
    pub seconds: f64,
    pub fed_updates: u64,
    pub python: Option<PathBuf>,
    pub pytorch: bool,
    pub json: bool,
}

/// The PyTorch script, relative to the repository root.
const SCRIPT: &str = "scripts/bench_learner_torch.py";

fn python(explicit: &Option<PathBuf>) -> PathBuf {
    if let Some(p) = explicit {
        return p.clone();
    }
    if let Some(p) = std::env::var_os("CROSSROADS_PYTHON") {
        return p.into();
    }
    let venv = PathBuf::from(".venv/bin/python3");
    if venv.exists() {
        return venv;
    }
    "python3".into()
}

fn script() -> Option<PathBuf> {
    let local = PathBuf::from(SCRIPT);
    if local.exists() {
        return Some(local);
    }
    // The repository root, one folder above this crate.
    let beside = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).join(SCRIPT);
    beside.exists().then_some(beside)
}

/// Runs the PyTorch twin; `Err` says why it could not.
fn pytorch(config: &Config, o: &LearnerBenchOptions) -> Result<serde_json::Value, String> {
    let spec = TrainerConfig::from_config(&config.sim, &config.learner)
        .map_err(|e| e.to_string())?
        .spec;
    let grid = &spec.observation;
    let conv = match spec.trunk {
        crossroads_model::TrunkKind::Mlp => String::new(),
        crossroads_model::TrunkKind::Conv => {
            format!(
                "{},{},{},{}",
                grid.channels, grid.rows, grid.cols, grid.extra
            )
        }
    };
    let l = &config.learner;
    let (optimizer, eps, decay) = match OptimizerConfig::from_config(l) {
        OptimizerConfig::Rmsprop { eps, decay, .. } => ("rmsprop", eps, decay),
        OptimizerConfig::Adam { eps, .. } => ("adam", eps, 0.0),
    };
    let script = script().ok_or_else(|| format!("{SCRIPT} not found (run from the repository)"))?;
    let python = python(&o.python);
    let hidden: Vec<String> = spec.hidden.iter().map(|h| h.to_string()).collect();
    let batches: Vec<String> = o.batches.iter().map(|b| b.to_string()).collect();
    let out = Command::new(&python)
        .arg(&script)
        .args(["--input", &spec.input_len().to_string()])
        .args(["--hidden", &hidden.join(",")])
        .args(["--conv", &conv])
        .args(["--actions", &spec.num_actions.to_string()])
        .args(["--batch", &batches.join(",")])
        .args(["--threads", &o.threads.to_string()])
        .args(["--rounds", &o.rounds.to_string()])
        .args(["--seconds", &o.seconds.to_string()])
        .args(["--optimizer", optimizer])
        .args(["--lr", &l.learning_rate.to_string()])
        .args(["--rmsprop-decay", &decay.to_string()])
        .args(["--eps", &eps.to_string()])
        .args([
            "--adam-betas",
            &format!("{},{}", l.adam_beta1, l.adam_beta2),
        ])
        .args(["--max-grad-norm", &l.max_grad_norm.to_string()])
        .args(["--target-period", &l.target_period.to_string()])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let last = err.lines().last().unwrap_or("").to_owned();
        return Err(format!("{} {}: {last}", python.display(), script.display()));
    }
    serde_json::from_slice(&out.stdout).map_err(|e| format!("unreadable PyTorch report: {e}"))
}

async fn fed_runs(
    config: &Config,
    o: &LearnerBenchOptions,
) -> anyhow::Result<Vec<(u32, FedReport)>> {
    let mut c = config.clone();
    c.replay.listen = ([127, 0, 0, 1], 0).into();
    c.replay.shm_ingest = false;
    c.replay.snapshot_dir = None;
    c.replay.min_size_to_sample = 1;
    c.replay.samples_per_insert = 0.0;
    c.replay.capacity = 50_000;
    c.runtime.torch_threads = o.threads;
    let shutdown = Shutdown::new();
    let server = crossroads_replay::start(&c, None, shutdown.clone())
        .await
        .context("starting a replay server")?;
    c.transport.replay_endpoint = format!("{}://{}", c.transport.tls.scheme(), server.local_addr());
    let client = ReplayClient::new(&c.transport, &c.replay.table)?;
    let spec = TrainerConfig::from_config(&c.sim, &c.learner)?.spec;
    fill_replay(&client, &spec, 20_000)
        .await
        .context("filling the replay server")?;
    let mut out = Vec::new();
    for &b in &o.batches {
        c.learner.batch_size = b;
        let report = fed(&c, o.fed_updates)
            .await
            .with_context(|| format!("learner fed over gRPC, batch {b}"))?;
        out.push((b, report));
    }
    shutdown.trigger();
    server.join().await.context("replay server")?;
    Ok(out)
}

/// Measures and prints.
pub fn run(config: &Config, o: &LearnerBenchOptions) -> anyhow::Result<ExitCode> {
    tch::set_num_threads(o.threads as i32);
    let load = super::load_average();
    let round = Duration::from_secs_f64(o.seconds.max(0.1));

    let mut memory = Vec::new();
    for &b in &o.batches {
        let mut l = config.learner.clone();
        l.batch_size = b;
        memory.push(updates_per_second(
            &config.sim,
            &l,
            config.runtime.precision,
            o.rounds,
            round,
        )?);
    }

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let fed = runtime.block_on(fed_runs(config, o))?;
    drop(runtime);

    let torch = if o.pytorch {
        Some(pytorch(config, o))
    } else {
        None
    };
    let torch_rate = |b: u32| -> Option<f64> {
        match &torch {
            Some(Ok(v)) => v["results"][b.to_string()]["updates_per_sec"].as_f64(),
            _ => None,
        }
    };

    let spec = TrainerConfig::from_config(&config.sim, &config.learner)?.spec;
    let precision = memory.first().map_or(Precision::F32, |m| m.precision);
    let network = format!(
        "{} actions ({}), {}, {precision}",
        super::describe_network(&spec),
        spec.observation.kind,
        OptimizerConfig::from_config(&config.learner).name()
    );
    if o.json {
        let rows: Vec<_> = o
            .batches
            .iter()
            .enumerate()
            .map(|(i, &b)| {
                let f = fed.iter().find(|(fb, _)| *fb == b).map(|(_, r)| r);
                json!({
                    "batch_size": b,
                    "updates_per_sec": memory[i].updates_per_sec,
                    "rounds": memory[i].rounds,
                    "fed_updates_per_sec": f.map(|r| r.updates_per_sec),
                    "fed_wait_fraction": f.map(|r| r.wait_fraction),
                    "pytorch_updates_per_sec": torch_rate(b),
                    "ratio_vs_pytorch": torch_rate(b).map(|t| memory[i].updates_per_sec / t),
                })
            })
            .collect();
        let torch_info = match &torch {
            Some(Ok(v)) => json!({"version": v["torch_version"], "threads": v["threads"]}),
            Some(Err(e)) => json!({"error": e}),
            None => json!(null),
        };
        println!(
            "{}",
            json!({
                "network": network,
                "precision": precision.name(),
                "threads": o.threads,
                "load_average": load,
                "results": rows,
                "pytorch": torch_info,
            })
        );
    } else {
        println!(
            "learner updates/s, {network}, {} threads, median of {} rounds of {:.1} s (load average {load})",
            o.threads,
            o.rounds,
            round.as_secs_f64()
        );
        println!("batch  updates/s  fed over gRPC  waiting  PyTorch  crossroads/PyTorch");
        for (i, &b) in o.batches.iter().enumerate() {
            let f = fed.iter().find(|(fb, _)| *fb == b).map(|(_, r)| r);
            let t = torch_rate(b);
            println!(
                "{:>5}  {:>9.1}  {:>13}  {:>7}  {:>7}  {:>18}",
                b,
                memory[i].updates_per_sec,
                f.map_or("-".into(), |r| format!("{:.1}", r.updates_per_sec)),
                f.map_or("-".into(), |r| format!("{:.1} %", 100.0 * r.wait_fraction)),
                t.map_or("-".into(), |t| format!("{t:.1}")),
                t.map_or("-".into(), |t| format!(
                    "{:.2}",
                    memory[i].updates_per_sec / t
                )),
            );
        }
        match &torch {
            Some(Ok(v)) => println!(
                "PyTorch {} on {} threads, same network, optimizer and loss, f32",
                v["torch_version"].as_str().unwrap_or("?"),
                v["threads"]
            ),
            Some(Err(e)) => println!("PyTorch comparison skipped: {e}"),
            None => {}
        }
    }
    Ok(ExitCode::SUCCESS)
}
