//! The command-line interface, as clap derives it.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use crossroads_common::ConfigLoader;

/// Learns to drive through unsignalized and occluded intersections with
/// distributed deep reinforcement learning (actors, prioritized replay, a
/// dueling double DQN learner).
#[derive(Debug, Parser)]
#[command(name = "crossroads", version, propagate_version = true)]
pub struct Cli {
    #[command(flatten)]
    pub global: GlobalArgs,
    #[command(subcommand)]
    pub command: Command,
}

/// Options every subcommand takes: where the configuration comes from.
#[derive(Debug, Clone, Args)]
pub struct GlobalArgs {
    /// TOML configuration file (one file describes a whole run; every role
    /// reads it). Environment variables CROSSROADS_<SECTION>__<KEY> override
    /// it, and --set overrides both.
    #[arg(
        long,
        short = 'c',
        global = true,
        env = "CROSSROADS_CONFIG",
        value_name = "FILE"
    )]
    pub config: Option<PathBuf>,

    /// Override one configuration key, e.g. --set runtime.worker_threads=4.
    /// Repeatable; applied after the file and the environment.
    #[arg(long = "set", short = 's', global = true, value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
}

impl GlobalArgs {
    /// The configuration layers these options describe.
    pub fn loader(&self) -> ConfigLoader {
        ConfigLoader::new()
            .file(self.config.as_ref())
            .sets(self.sets.iter().cloned())
    }
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Show the effective configuration, or check that it is valid.
    Config(ConfigArgs),
    /// Check this machine: libtorch, threads, and a timed forward pass.
    Doctor(DoctorArgs),
}

/// `crossroads config`.
#[derive(Debug, Args)]
pub struct ConfigArgs {
    #[command(subcommand)]
    pub action: ConfigAction,
}

#[derive(Debug, Subcommand)]
pub enum ConfigAction {
    /// Print the effective configuration (defaults, file, environment and
    /// --set merged) as TOML.
    Show,
    /// Validate the configuration and report every problem; exit status 0
    /// when it is valid.
    Check,
}

/// `crossroads doctor`.
#[derive(Debug, Args)]
pub struct DoctorArgs {
    /// Print the report as one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}
