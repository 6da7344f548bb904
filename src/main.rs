//! The `crossroads` binary: parses the command line and hands over to the
//! library. See `crossroads --help`.

use std::process::ExitCode;

use clap::Parser;
use crossroads::cli::{Cli, every_set};

fn main() -> ExitCode {
    let mut cli = Cli::parse();
    // clap keeps only the last group of a global flag given both before
    // and after the subcommand; every --set counts.
    cli.global.sets = every_set(std::env::args_os().skip(1));
    match crossroads::run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
