//! The `crossroads` binary: parses the command line and hands over to the
//! library. See `crossroads --help`.

use std::process::ExitCode;

use clap::Parser;
use crossroads::cli::{Cli, every_set};

fn main() -> ExitCode {
    passive_openmp();
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

/// libtorch's OpenMP (libgomp) reads `OMP_WAIT_POLICY` once, as the binary
/// loads, before `main`. Its default keeps idle threads spinning, and on a
/// machine where another process is busy those spinning threads starve the
/// ones with work: a forward pass 41x slower on this project's 2-core
/// machine. So unless the user chose a policy, every command re-executes
/// this binary once (same process id, arguments and environment) with
/// `OMP_WAIT_POLICY=passive`, before any thread or file is opened. If that
/// fails the command runs on, with a warning.
fn passive_openmp() {
    use std::os::unix::process::CommandExt;
    const VAR: &str = "OMP_WAIT_POLICY";
    if std::env::var_os(VAR).is_some() {
        return;
    }
    let mut args = std::env::args_os();
    let argv0 = args.next().unwrap_or_else(|| "crossroads".into());
    let error = match std::env::current_exe() {
        Ok(exe) => std::process::Command::new(exe)
            .arg0(argv0)
            .args(args)
            .env(VAR, "passive")
            .exec(),
        Err(e) => e,
    };
    eprintln!(
        "warning: could not re-execute with {VAR}=passive ({error}); libtorch's idle threads \
         will spin, which is slow on a busy machine: set {VAR}=passive yourself"
    );
}
