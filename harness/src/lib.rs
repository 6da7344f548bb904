//! The experiment harness: what `crossroads` runs around the roles, as a
//! library the binary calls with its parsed flags.
//!
//! - [`train`]: a whole training run on this machine (every role a child
//!   process, the watch loop, greedy evaluations, the run folder).
//! - [`reproduce`]: the paper's tables, Figure 3 and the safety across
//!   drivers: trains what is missing, evaluates and writes the reports.
//! - [`eval`] and [`tune_ttc`]: a policy over seeded trials, the TTC
//!   threshold sweep; [`sumo_check`]: our simulator against SUMO;
//!   [`bench`]: throughput, memory and time to target.
//! - [`experiments`]: the paper's run configurations, built in;
//!   [`global`]: the options every command takes;
//!   [`network_policy`]: a trained Q-network (or an ensemble) as a
//!   `crossroads_sim::Policy`; [`role`]: the runtime, signals and metrics
//!   endpoint a role process shares; [`child`]: this program started as
//!   a child ([`child::TrainingChild`]); [`progress`]: progress bars.
//!
//! Each command's clap `Args` struct lives beside its `run`, so the binary
//! only assembles them (`src/cli.rs`).

pub mod bench;
pub mod child;
pub mod eval;
pub mod experiments;
pub mod global;
pub mod network_policy;
pub mod progress;
pub mod reproduce;
pub mod role;
pub mod sumo_check;
pub mod train;
pub mod tune_ttc;
