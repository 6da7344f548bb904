//! The learner: dueling double DQN trained from the replay server, weight
//! broadcast to actors, checkpoints and their gRPC API. Never steps a
//! simulator.
//!
//! [`sampler::spawn_prefetch`] samples batches from the replay over gRPC in
//! the background into [`TrainingBatch`]es; the training thread
//! ([`training::Learner`]) runs [`Trainer::update`] on them (double-DQN
//! n-step targets under `no_grad`, importance-weighted Huber loss,
//! [`Optimizer`] step with gradient clipping, target update), hands the new
//! priorities to [`sampler::spawn_priority_sender`], publishes versioned
//! weights (into a `crossroads_transport::WeightsSlot` read by the gRPC
//! stream, and over iceoryx2 to actors on this host) and writes
//! [`CheckpointStore`] checkpoints. The tonic service (private: no prost
//! type in this crate's API) serves weights, checkpoints and status; its
//! client is `crossroads_transport::LearnerClient`. [`start`] / [`run`] put
//! it together under one shutdown signal; [`bench`](mod@bench) measures
//! updates per second. Configuration: [`crossroads_config::LearnerConfig`],
//! and `runtime.device` for where networks, batches and optimizer state
//! live ([`Trainer::new_on`]; what is published or stored is on the CPU).

pub mod batch;
pub mod bench;
pub mod checkpoint;
mod error;
pub mod metrics;
pub mod optimizer;
pub mod sampler;
pub mod server;
mod service;
pub mod targets;
pub mod trainer;
pub mod training;

pub use batch::TrainingBatch;
pub use checkpoint::{CheckpointStore, StoreError};
pub use error::LearnerError;
pub use metrics::LearnerMetrics;
pub use optimizer::{Optimizer, OptimizerConfig};
pub use server::{RunningLearner, run, start};
pub use trainer::{EarlyPhase, GoLabels, Trainer, TrainerConfig, UpdateStats};
