//! One module per subcommand that the binary runs itself; the experiment
//! harness's commands (`train`, `reproduce`, `bench`, `eval`, `tune-ttc`,
//! `sumo-check`) are `crossroads_harness`'s.

pub mod actor;
pub mod checkpoints;
pub mod config;
pub mod docs;
pub mod doctor;
pub mod health;
pub mod learner;
pub mod render;
pub mod replay;
