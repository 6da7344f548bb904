//! End-to-end tests of the `crossroads` binary and the repository's scripts,
//! one test binary.

mod cli;
mod deploy;
mod docs;
mod experiments;
mod faults;
mod graph;
mod learner;
mod readme;
mod replay;
mod reproduce;
mod security;
mod setup_libtorch;
mod sim_commands;
mod sumo;
mod train;

/// The binary under test, run without the `CROSSROADS_*` variables of
/// this process's environment.
pub fn crossroads() -> crossroads_test_support::Crossroads {
    crossroads_test_support::Crossroads::new(env!("CARGO_BIN_EXE_crossroads"))
}
