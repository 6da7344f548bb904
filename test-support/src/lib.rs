//! What the workspace's tests share, so that each helper is written once: a
//! dev-dependency only, never a normal one.
//!
//! - [`Crossroads`]: the `crossroads` binary, whose path the caller gives
//!   (`env!("CARGO_BIN_EXE_crossroads")` exists only in the root package's
//!   tests), as a [`std::process::Command`] with no `CROSSROADS_*` variable
//!   of the test's environment.
//! - [`RoleProcess`]: a role started from such a command, its log lines on
//!   a channel, the address it logs, SIGTERM then (on drop) SIGKILL.
//! - [`gates`]: the environment variables that gate tests (the slow
//!   trainings, the tools some tests need), read one way.
//! - [`fixtures`]: [`toy_batch`] and [`crash_copy`].

pub mod crossroads;
pub mod fixtures;
pub mod gates;
pub mod role_process;

pub use crossroads::Crossroads;
pub use fixtures::{crash_copy, toy_batch};
pub use gates::Need;
pub use role_process::RoleProcess;
