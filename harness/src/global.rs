//! The options every `crossroads` command takes: where the configuration
//! comes from (a file, a built-in experiment, `--set`), and the layers
//! they describe.

use std::path::PathBuf;

use clap::Args;
use crossroads_config::ConfigLoader;

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

    /// Start from a built-in experiment of configs/experiments/ (ttg-left,
    /// sequential-right, ...): its settings lie under the file, the
    /// environment and --set. How a container of a scaled run picks the
    /// paper's tuned settings without a file.
    #[arg(
        long,
        global = true,
        env = "CROSSROADS_EXPERIMENT",
        value_name = "NAME",
        value_parser = experiment_name
    )]
    pub experiment: Option<String>,

    /// Override one configuration key, e.g. --set runtime.worker_threads=4.
    /// Repeatable; applied after the file and the environment.
    #[arg(long = "set", short = 's', global = true, value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
}

/// Every `--set KEY=VALUE` (also `--set=KEY=VALUE` and `-s KEY=VALUE`) of
/// a command line, in order, wherever it stands: clap keeps only the group
/// after the subcommand when a global flag appears on both sides of it.
/// Stops at `--`.
pub fn every_set(args: impl IntoIterator<Item = std::ffi::OsString>) -> Vec<String> {
    let mut sets = Vec::new();
    let mut args = args.into_iter().map(|a| a.to_string_lossy().into_owned());
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--" => break,
            "--set" | "-s" => sets.extend(args.next()),
            _ => {
                if let Some(v) = arg.strip_prefix("--set=") {
                    sets.push(v.to_owned());
                }
            }
        }
    }
    sets
}

impl GlobalArgs {
    /// The configuration layers these options describe.
    pub fn loader(&self) -> ConfigLoader {
        let mut loader = ConfigLoader::new();
        if let Some(e) = self
            .experiment
            .as_deref()
            .and_then(crate::experiments::named)
        {
            loader = loader.base(format!("built-in experiment {}", e.name), e.toml);
        }
        loader
            .file(self.config.as_ref())
            .sets(self.sets.iter().cloned())
    }
}

/// A built-in experiment's name, or an error listing them.
fn experiment_name(name: &str) -> Result<String, String> {
    match crate::experiments::named(name) {
        Some(e) => Ok(e.name.to_owned()),
        None => Err(format!(
            "no built-in experiment {name:?}; there are {}",
            crate::experiments::EXPERIMENTS
                .iter()
                .map(|e| e.name)
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}
