//! End-to-end tests of the `crossroads` binary and the repository's scripts,
//! one test binary.

mod cli;
mod deploy;
mod docs;
mod experiments;
mod faults;
mod graph;
mod learner;
mod procs;
mod readme;
mod replay;
mod reproduce;
mod security;
mod setup_libtorch;
mod sim_commands;
mod sumo;
mod train;

/// Whether the slow end-to-end tests run: `CROSSROADS_SLOW_TESTS=1`, as
/// `make test` sets. Without it a slow test prints why it is skipped and
/// returns; a quick twin covers the same path at a small budget.
pub fn slow_tests_enabled(test: &str) -> bool {
    if std::env::var("CROSSROADS_SLOW_TESTS").is_ok_and(|v| v == "1") {
        return true;
    }
    // Straight to the process's stderr: libtest captures only the print
    // macros, so the line shows in a passing run too.
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "skipped: set CROSSROADS_SLOW_TESTS=1 to run {test} (a slow end-to-end training)"
    );
    false
}
