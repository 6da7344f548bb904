//! One module per subcommand.

pub mod actor;
pub mod bench;
pub mod checkpoints;
pub mod config;
pub mod docs;
pub mod doctor;
pub mod eval;
pub mod health;
pub mod learner;
pub mod render;
pub mod replay;
pub mod reproduce;
pub mod role;
pub mod sumo_check;
pub mod train;
pub mod tune_ttc;
