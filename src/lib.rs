//! The `crossroads` command line: one binary with a subcommand per role, so
//! one container image serves every role.
//!
//! [`cli::Cli`] is the clap definition; [`run`] loads the layered
//! configuration ([`crossroads_config::ConfigLoader`]), starts tracing and
//! dispatches: the roles, `config`, `doctor`, `health`, `checkpoints`,
//! `render` and `docs` to their module under [`commands`], the experiment
//! harness's commands to `crossroads_harness`.

pub mod cli;
pub mod commands;

use std::process::ExitCode;

use anyhow::Context;
use cli::{Cli, Command};

/// Runs one parsed command line to completion.
pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let loader = match &cli.command {
        Command::Replay(args) => args.apply(cli.global.loader()),
        Command::Learner(args) => args.apply(cli.global.loader()),
        Command::Actor(args) => args.apply(cli.global.loader()),
        Command::Train(args) => args.loader(&cli.global),
        Command::Doctor(_) => commands::doctor::loader(&cli.global),
        _ => cli.global.loader(),
    };
    let mut config = loader.load().context("loading configuration")?;
    if matches!(
        cli.command,
        Command::Learner(_) | Command::Actor(_) | Command::Train(_) | Command::Bench(_)
    ) {
        // The network reads what the actors produce: derived once, here.
        crossroads_actor::resolve_observation(&mut config.sim).context("loading configuration")?;
    }
    crossroads_common::telemetry::init_tracing(config.telemetry.log_format)?;
    if config.runtime.compute_threads > 0 {
        rayon::ThreadPoolBuilder::new()
            .num_threads(config.runtime.compute_threads)
            .build_global()
            .context("starting the compute thread pool")?;
    }
    match cli.command {
        Command::Config(args) => commands::config::run(&cli.global, &config, &args),
        Command::Doctor(args) => commands::doctor::run(&cli.global, &config, &args),
        Command::Eval(args) => crossroads_harness::eval::run(&args),
        Command::Health(args) => commands::health::run(&config, &args),
        Command::TuneTtc(args) => crossroads_harness::tune_ttc::run(&args),
        Command::SumoCheck(args) => crossroads_harness::sumo_check::run(&args),
        Command::Render(args) => commands::render::run(&args),
        Command::Replay(_) => commands::replay::run(&config),
        Command::Bench(args) => crossroads_harness::bench::run(&cli.global, &config, &args),
        Command::Learner(_) => commands::learner::run(&config),
        Command::Checkpoints(args) => commands::checkpoints::run(&config, &args),
        Command::Actor(args) => commands::actor::run(&config, &args),
        Command::Train(args) => crossroads_harness::train::run(&cli.global, &config, &args),
        Command::Reproduce(args) => crossroads_harness::reproduce::run(&cli.global, &args),
        Command::Docs(args) => commands::docs::run(&args),
    }
}
