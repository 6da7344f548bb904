//! `crossroads config show|check`.

use std::process::ExitCode;

use crossroads_config::Config;
use crossroads_harness::global::GlobalArgs;

use crate::cli::{ConfigAction, ConfigArgs};

/// Prints or checks the configuration already loaded (loading it is where
/// problems are found, so reaching here means it is valid).
pub fn run(global: &GlobalArgs, config: &Config, args: &ConfigArgs) -> anyhow::Result<ExitCode> {
    match args.action {
        ConfigAction::Show => print!("{}", config.to_toml()),
        ConfigAction::Check => match &global.config {
            Some(path) => println!("ok: {} is a valid configuration", path.display()),
            None => println!("ok: the default configuration (with environment and --set) is valid"),
        },
    }
    Ok(ExitCode::SUCCESS)
}
