//! `crossroads bench time-to-target`: how long `crossroads train` takes to
//! confirm an experiment's target on this machine, from several seeds.
//!
//! Each seed is one `crossroads train` child (this binary) with
//! `actor.seed` and `learner.seed` set to it and `train.stop_at_target`,
//! into its own run folder; the figures come from the run's
//! `summary.json` (the confirming evaluation's clocks). A seed that does
//! not confirm the target within `--minutes` counts as not reached, and
//! the medians are over the seeds that reached it. Ctrl-C or SIGTERM
//! stops the seed in training cleanly and ends the bench.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use crossroads_common::Shutdown;
use serde_json::json;

use crate::child::{self, TrainingChild, TrainingExit};
use crate::experiments::{self, DEFAULT_EXPERIMENT};
use crate::global::GlobalArgs;
use crate::train::record::{RunStatus, Summary};

/// What to measure.
#[derive(Debug, Clone)]
pub struct TimeToTargetOptions {
    /// Training seeds.
    pub seeds: Vec<u64>,
    /// Budget per seed.
    pub minutes: f64,
    /// Where the run folders go (a temporary folder when `None`).
    pub out: Option<PathBuf>,
    /// Print one JSON object.
    pub json: bool,
}

/// One seed's training.
#[derive(Debug)]
struct Outcome {
    seed: u64,
    /// The run's status at its end.
    status: RunStatus,
    /// Wall seconds, env steps and updates at the confirming evaluation.
    reached: Option<(f64, u64, u64)>,
    /// The whole training, start to exit.
    wall_seconds: f64,
    folder: PathBuf,
}

/// The median of `values` (the mean of the middle two for an even count);
/// `None` when empty.
fn median(mut values: Vec<f64>) -> Option<f64> {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(values[n / 2]),
        _ => Some((values[n / 2 - 1] + values[n / 2]) / 2.0),
    }
}

/// Trains `seed` into `folder` and reads what its summary says.
fn train(
    global: &GlobalArgs,
    o: &TimeToTargetOptions,
    seed: u64,
    folder: &Path,
    shutdown: &Shutdown,
) -> anyhow::Result<Outcome> {
    let mut args: Vec<OsString> = Vec::new();
    if let Some(file) = &global.config {
        args.extend(["--config".into(), file.into()]);
    }
    let experiment = global.experiment.clone().or_else(|| {
        global
            .config
            .is_none()
            .then(|| DEFAULT_EXPERIMENT.to_owned())
    });
    if let Some(e) = experiment {
        args.extend(["--experiment".into(), e.into()]);
    }
    for set in &global.sets {
        args.extend(["--set".into(), set.into()]);
    }
    for set in [
        format!("actor.seed={seed}"),
        format!("learner.seed={seed}"),
        "train.stop_at_target=true".to_owned(),
    ] {
        args.extend(["--set".into(), set.into()]);
    }
    args.extend([
        "train".into(),
        "--out".into(),
        folder.into(),
        "--minutes".into(),
        o.minutes.to_string().into(),
    ]);
    std::fs::create_dir_all(folder).with_context(|| format!("creating {}", folder.display()))?;
    let log_path = folder.with_extension("log");
    let log = std::fs::File::create(&log_path)
        .with_context(|| format!("creating {}", log_path.display()))?;
    let started = Instant::now();
    let status = match TrainingChild::start(&args, Some(log))?.wait(shutdown)? {
        TrainingExit::Exited(status) => status,
        TrainingExit::Stopped(status) => {
            anyhow::bail!("stopped while training seed {seed} ({status})")
        }
    };
    let wall_seconds = started.elapsed().as_secs_f64();
    let summary = Summary::load(folder)?;
    let Some(summary) = summary.filter(|_| status.success()) else {
        anyhow::bail!(
            "seed {seed}: crossroads train failed ({status}); its output is in {}",
            log_path.display()
        );
    };
    Ok(Outcome {
        seed,
        status: summary.status,
        reached: summary.reached.map(|r| {
            let e = r.evaluation;
            (e.wall_seconds, e.env_steps, e.updates)
        }),
        wall_seconds,
        folder: folder.to_path_buf(),
    })
}

/// Trains every seed and prints the figures.
pub fn run(global: &GlobalArgs, o: &TimeToTargetOptions) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(!o.seeds.is_empty(), "--seeds: give at least one seed");
    anyhow::ensure!(
        o.minutes > 0.0 && o.minutes.is_finite(),
        "--minutes: {} is not a positive number of minutes",
        o.minutes
    );
    let what = match (&global.experiment, &global.config) {
        (Some(e), _) => format!("experiment {e}"),
        (None, Some(file)) => file.display().to_string(),
        (None, None) => format!("experiment {DEFAULT_EXPERIMENT}"),
    };
    // What each child will train, checked here: without a target a seed
    // would train its whole budget for nothing.
    let loader = match (&global.experiment, &global.config) {
        (None, None) => {
            let e = experiments::named(DEFAULT_EXPERIMENT)
                .context("the default experiment is built in")?;
            crossroads_config::ConfigLoader::new()
                .base(format!("built-in experiment {}", e.name), e.toml)
                .sets(global.sets.iter().cloned())
        }
        _ => global.loader(),
    };
    let config = loader.load().context("loading the configuration")?;
    anyhow::ensure!(
        config.train.target_success > 0.0,
        "{what} sets no target (train.target_success = 0), so there is no time to it to \
         measure: give one with --set train.target_success=... (and train.target_collision, \
         train.target_time_s), as configs/experiments/ttg-left.toml does"
    );
    let scratch;
    let root = match &o.out {
        Some(dir) => dir.clone(),
        None => {
            scratch = tempfile::tempdir().context("creating a temporary folder")?;
            scratch.path().to_path_buf()
        }
    };
    let (_signals, shutdown) = child::on_signals()?;
    let machine = crate::train::session::machine();
    let load = super::load_average();
    let mut outcomes = Vec::new();
    for (i, &seed) in o.seeds.iter().enumerate() {
        let folder = root.join(format!("seed-{seed}"));
        eprintln!(
            "time to target: {what}, seed {seed} ({} of {}), at most {} min, into {}",
            i + 1,
            o.seeds.len(),
            o.minutes,
            folder.display()
        );
        let outcome = train(global, o, seed, &folder, &shutdown)?;
        match outcome.reached {
            Some((secs, steps, updates)) => {
                eprintln!("  reached after {secs:.0} s, {steps} env steps, {updates} updates")
            }
            None => eprintln!(
                "  not reached in {:.0} s (run {:?})",
                outcome.wall_seconds, outcome.status
            ),
        }
        outcomes.push(outcome);
    }
    let reached: Vec<_> = outcomes.iter().filter_map(|o| o.reached).collect();
    let median_secs = median(reached.iter().map(|r| r.0).collect());
    let median_steps = median(reached.iter().map(|r| r.1 as f64).collect());
    let median_updates = median(reached.iter().map(|r| r.2 as f64).collect());
    if o.json {
        let rows: Vec<_> = outcomes
            .iter()
            .map(|r| {
                json!({
                    "seed": r.seed,
                    "status": r.status,
                    "reached": r.reached.is_some(),
                    "wall_seconds_to_target": r.reached.map(|x| x.0),
                    "env_steps_to_target": r.reached.map(|x| x.1),
                    "updates_to_target": r.reached.map(|x| x.2),
                    "wall_seconds": r.wall_seconds,
                    "folder": o.out.as_ref().map(|_| r.folder.display().to_string()),
                })
            })
            .collect();
        println!(
            "{}",
            json!({
                "trained": what,
                "machine": machine,
                "load_average": load,
                "minutes_per_seed": o.minutes,
                "seeds": rows,
                "reached": reached.len(),
                "median_wall_seconds": median_secs,
                "median_env_steps": median_steps,
                "median_updates": median_updates,
            })
        );
    } else {
        println!(
            "time to target, {what}, {} seeds, at most {} min each ({machine}; load average {load})",
            o.seeds.len(),
            o.minutes
        );
        println!("seed  reached  wall s  env steps  updates");
        for r in &outcomes {
            match r.reached {
                Some((secs, steps, updates)) => {
                    println!(
                        "{:>4}  {:>7}  {secs:>6.0}  {steps:>9}  {updates:>7}",
                        r.seed, "yes"
                    );
                }
                None => println!(
                    "{:>4}  {:>7}  {:>6}  {:>9}  {:>7}",
                    r.seed, "no", "-", "-", "-"
                ),
            }
        }
        match (median_secs, median_steps, median_updates) {
            (Some(s), Some(e), Some(u)) => println!(
                "median over the {} that reached it: {s:.0} s, {e:.0} env steps, {u:.0} updates",
                reached.len()
            ),
            _ => println!("no seed reached the target"),
        }
        if let Some(dir) = &o.out {
            println!(
                "runs in {} (each seed-N/reached/ holds the network that confirmed the target)",
                dir.display()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::median;

    #[test]
    fn median_of_odd_even_and_empty_counts() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(vec![]), None);
    }
}
