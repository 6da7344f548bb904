//! The `crossroads` binary: parses the command line and hands over to the
//! library. See `crossroads --help`.

use std::process::ExitCode;

use clap::Parser;
use crossroads::cli::Cli;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match crossroads::run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
