//! The `crossroads` binary: parses the command line and hands over to the
//! library. See `crossroads --help`.

use std::process::ExitCode;

use clap::FromArgMatches;
use crossroads::cli::Cli;
use crossroads_harness::global::every_set;

fn main() -> ExitCode {
    load_time_settings();
    // Parsed with the flags' configuration keys in their help.
    let mut parser = crossroads::cli::command();
    let mut cli = Cli::from_arg_matches(&parser.get_matches_mut())
        .unwrap_or_else(|e| e.format(&mut parser).exit());
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

/// Settings the C libraries under libtorch read once, as the binary loads,
/// before `main`; each applies unless the user set the variable (an empty
/// value counts as set).
///
/// - `OMP_WAIT_POLICY=passive`: libgomp's default keeps idle threads
///   spinning, and on a machine where another process is busy those
///   spinning threads starve the ones with work.
/// - [`MALLOC_TUNABLES`] in `GLIBC_TUNABLES`: glibc returns the top of its
///   heap to the system whenever more than a few megabytes are free there,
///   and a conv update frees that much every step, so the next one faults
///   its pages in again.
///
/// Figures for both: reports/performance/README.md ("OpenMP wait policy",
/// "glibc heap thresholds").
const LOAD_TIME_SETTINGS: [(&str, &str); 2] = [
    ("OMP_WAIT_POLICY", "passive"),
    ("GLIBC_TUNABLES", MALLOC_TUNABLES),
];

/// Allocations of up to 16 MiB come from the heap (not a mapping of their
/// own), and the heap is trimmed only when 32 MiB at its top are free. A
/// fixed value also turns off glibc's own adjustment of both.
const MALLOC_TUNABLES: &str =
    "glibc.malloc.mmap_threshold=16777216:glibc.malloc.trim_threshold=33554432";

/// Every command re-executes this binary once (same process id, arguments
/// and environment) with the [`LOAD_TIME_SETTINGS`] the user left unset,
/// before any thread or file is opened. If that fails the command runs on,
/// with a warning.
fn load_time_settings() {
    use std::os::unix::process::CommandExt;
    let missing: Vec<(&str, &str)> = LOAD_TIME_SETTINGS
        .into_iter()
        .filter(|(var, _)| std::env::var_os(var).is_none())
        .collect();
    if missing.is_empty() {
        return;
    }
    let mut args = std::env::args_os();
    let argv0 = args.next().unwrap_or_else(|| "crossroads".into());
    let error = match std::env::current_exe() {
        Ok(exe) => std::process::Command::new(exe)
            .arg0(argv0)
            .args(args)
            .envs(missing.iter().copied())
            .exec(),
        Err(e) => e,
    };
    let vars: Vec<String> = missing.iter().map(|(k, v)| format!("{k}={v}")).collect();
    eprintln!(
        "warning: could not re-execute with {} ({error}); libtorch's idle threads may spin \
         (slow on a busy machine) and its buffers fault their pages in every step: set them \
         yourself",
        vars.join(" ")
    );
}
