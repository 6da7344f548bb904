//! Every conversation between crossroads processes, gRPC and iceoryx2, in
//! both directions, spoken in domain types.
//!
//! - [`grpc`]: [`ReplayClient`], the replay server's client on any host:
//!   for actors (streaming insert with acknowledgements, joining), the
//!   learner (sample, update priorities) and the CLI (info, snapshots).
//! - [`learner_client`]: [`LearnerClient`], the learner service's client
//!   (weights for actors; status, evaluations and checkpoints for the CLI).
//! - [`shm`] ([`ShmBatchPublisher`]) and [`weights_shm`]: batches and weights
//!   in iceoryx2 shared memory on one host; [`iox`] opens their services.
//! - [`weights_slot`]: [`WeightsSlot`], the newest weights a process holds.
//! - [`wire`] (batches, samples, table descriptions) and [`convert`] (specs,
//!   weights, [`CheckpointSummary`]): the domain to and from
//!   `crossroads_proto`, validating at the boundary.
//! - [`security`] ([`ServerSecurity`], [`ClientSecurity`]), [`auth`] (the
//!   token) and [`channel`] (the one place a gRPC channel is built).
//!
//! Links no tch (weights travel as safetensors bytes), so the replay has no
//! libtorch; prost types appear only in [`wire`] and [`convert`].

pub mod auth;
pub mod channel;
pub mod convert;
pub mod grpc;
pub mod iox;
pub mod learner_client;
pub mod security;
pub mod shm;
pub mod weights_shm;
pub mod weights_slot;
pub mod wire;

pub use convert::CheckpointSummary;
pub use grpc::{
    ClientError, InsertAck, InsertStream, JoinedActor, RateLimiterInfo, ReplayClient,
    SnapshotWritten, TableInfo,
};
pub use learner_client::{LearnerClient, LearnerClientError, LearnerStatus, WeightsStream};
pub use security::{ClientSecurity, SecurityError, ServerSecurity};
pub use shm::{ShmBatchPublisher, ShmError};
pub use weights_shm::{ShmWeightsPublisher, ShmWeightsSubscriber};
pub use weights_slot::{WeightsSlot, WeightsWatch};
