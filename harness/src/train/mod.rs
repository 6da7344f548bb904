//! `crossroads train`: a whole training run on this machine, with the same
//! roles and transports as a distributed one.
//!
//! It writes `<out>/config.toml`, starts the replay, the learner and
//! `actor.count` actors from this binary (each in its own process group,
//! logging to `<out>/logs/`) and watches them over gRPC and `/metrics`
//! behind a progress bar. Every `train.eval_every` updates it runs
//! `train.eval_trials` seeded greedy trials in this process (at most
//! `train.eval_share` of the wall time) into `<out>/curve.csv`; weights
//! that beat the best return or meet the target are re-measured on
//! `train.confirm_trials` trials and the best kept in `<out>/best/`. It
//! ends at the update or time budget, the target (`train.stop_at_target`)
//! or Ctrl-C, stopping actors, learner and replay in that order. The parts,
//! in the order a run meets them: this module (flags), [`prepare`],
//! [`session`] (with [`procs`]), [`watch`], [`evaluate`], [`record`].

mod evaluate;
mod prepare;
mod procs;
pub(crate) mod record;
pub(crate) mod session;
mod watch;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use crossroads_config::{Config, ConfigLoader};

pub use self::record::write_atomic;
pub use self::record::{Evaluation, RunStatus, Summary, curve_panel, read_curve};
pub use self::session::{machine, sum_metric};
use crate::global::{GlobalArgs, KeyFlag, layer};
use crate::key_flag;
use crate::role;

/// `crossroads train`. Each flag overrides the configuration key it names.
#[derive(Debug, Clone, Args)]
pub struct TrainArgs {
    /// Scenario.
    #[arg(long, value_name = "NAME|FILE")]
    pub scenario: Option<String>,
    /// Action set: ttg, sequential or creep; the observation and the
    /// network follow.
    #[arg(long, value_name = "SET")]
    pub actions: Option<String>,
    /// Actor processes.
    #[arg(long, value_name = "N")]
    pub actors: Option<u32>,
    /// Environments per actor.
    #[arg(long, value_name = "M")]
    pub envs: Option<usize>,
    /// Update budget; 0 trains until Ctrl-C.
    #[arg(long, value_name = "N")]
    pub updates: Option<u64>,
    /// Wall-clock budget in minutes.
    #[arg(long, value_name = "MIN")]
    pub minutes: Option<f64>,
    /// Run folder [default: runs/<experiment> with --experiment, else
    /// runs/<actions>-<scenario>].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Continue the run in the folder: its config.toml (unless --config),
    /// newest checkpoint, replay snapshot, curve and clocks.
    #[arg(long)]
    pub resume: bool,
}

/// The run folder a run of `scenario` with `actions` gets by default:
/// `runs/<actions>-<scenario>`, the built-in experiment's name (a scenario
/// file contributes its stem).
pub fn default_out(scenario: &str, actions: &str) -> PathBuf {
    let stem = Path::new(scenario)
        .file_stem()
        .map_or_else(|| scenario.to_owned(), |s| s.to_string_lossy().into_owned());
    PathBuf::from("runs").join(format!("{actions}-{stem}"))
}

impl TrainArgs {
    /// The flags that set a configuration key.
    pub const KEYS: &'static [KeyFlag<Self>] = &[
        key_flag!(scenario => "sim.scenario"),
        key_flag!(actions => "sim.action_set"),
        key_flag!(actors => "actor.count"),
        key_flag!(envs => "actor.envs"),
        key_flag!(updates => "learner.max_updates"),
        key_flag!(minutes => "train.max_minutes"),
    ];

    /// The run folder: `--out`, else `runs/<experiment>` with
    /// `--experiment`, else [`default_out`] of `scenario` and `actions`.
    fn run_folder(&self, global: &GlobalArgs, scenario: &str, actions: &str) -> PathBuf {
        match (&self.out, &global.experiment) {
            (Some(out), _) => out.clone(),
            (None, Some(e)) => PathBuf::from("runs").join(e),
            (None, None) => default_out(scenario, actions),
        }
    }

    /// The run folder these flags name, before the config is read.
    fn out_dir(&self, global: &GlobalArgs) -> PathBuf {
        self.run_folder(
            global,
            self.scenario.as_deref().unwrap_or("left"),
            self.actions.as_deref().unwrap_or("ttg"),
        )
    }

    /// The built-in experiment these flags name (default: ttg on left).
    pub fn experiment(&self) -> Option<crate::experiments::Experiment> {
        crate::experiments::find(
            self.actions.as_deref().unwrap_or("ttg"),
            self.scenario.as_deref().unwrap_or("left"),
        )
    }

    /// The configuration layers of a run: with `--resume` and no
    /// `--config`, the run folder's `config.toml` is the file; then these
    /// flags. Without a file, the paper's experiment for the scenario and action
    /// set (configs/experiments/, built in) is the base, so that plain
    /// `crossroads train` trains DQN-TTG on left with tuned settings.
    pub fn loader(&self, global: &GlobalArgs) -> ConfigLoader {
        let mut loader = global.loader();
        let saved = self.out_dir(global).join("config.toml");
        if self.resume && global.config.is_none() && saved.exists() {
            loader = loader.file(Some(saved));
        } else if global.config.is_none()
            && global.experiment.is_none()
            && let Some(e) = self.experiment()
        {
            loader = loader.base(format!("built-in experiment {}", e.name), e.toml);
        }
        layer(self, Self::KEYS, loader)
    }
}

/// Runs the training job, into `--out`, else `runs/<experiment>` with
/// `--experiment`, else `runs/<actions>-<scenario>` of the configuration.
pub fn run(global: &GlobalArgs, config: &Config, args: &TrainArgs) -> anyhow::Result<ExitCode> {
    let out = args.run_folder(global, &config.sim.scenario, &config.sim.action_set);
    let run = prepare::prepare(config, &out, args.resume)?;
    role::block_on(config, async move { session::train(run).await })
}
