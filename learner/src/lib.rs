//! The learner: dueling double DQN trained from the replay server, weight
//! broadcast to actors, checkpoints and their gRPC API. Never steps a
//! simulator.
//!
//! Data flow: [`sampler::spawn_prefetch`] samples batches from the replay
//! server over gRPC in the background and decodes them into
//! [`TrainingBatch`]es; the training thread ([`training::Learner`]) takes
//! them and runs [`Trainer::update`] (double-DQN n-step targets under
//! `no_grad`, importance-weighted Huber loss, [`Optimizer`] step with
//! gradient clipping, target-network update), hands the new priorities to
//! [`sampler::spawn_priority_sender`], and on its schedules publishes the
//! weights (a monotonic version, into a
//! `crossroads_transport::WeightsSlot` that the gRPC stream reads, and
//! `crossroads_transport::weights_shm::ShmWeightsPublisher` for actors on
//! this host) and writes checkpoints ([`CheckpointStore`]:
//! safetensors weights, target network and optimizer state plus a JSON
//! manifest, written atomically). The tonic service (private: no prost
//! type is in this crate's API) serves weights, checkpoints and status;
//! its client (`LearnerClient`) and the conversions to and from the wire
//! are in `crossroads_transport`. [`start`] / [`run`] put it all together
//! under one shutdown signal. [`bench`](mod@bench) measures updates per
//! second and the time spent waiting for samples.
//!
//! The whole configuration is the `[learner]` section
//! ([`crossroads_config::LearnerConfig`]), with `runtime.device` for where
//! the networks, batches and optimizer state live (the CPU or CUDA device
//! 0, [`Trainer::new_on`]; everything published or stored comes back to
//! the CPU).

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
pub use trainer::{EarlyPhase, Trainer, TrainerConfig, UpdateStats};
