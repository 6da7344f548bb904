//! End-to-end tests of the `crossroads` binary and the repository's scripts,
//! one test binary.

mod cli;
mod deploy;
mod experiments;
mod graph;
mod learner;
mod replay;
mod reproduce;
mod setup_libtorch;
mod sim_commands;
mod sumo;
mod train;
