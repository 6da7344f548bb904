//! Every conversation between crossroads processes, gRPC and iceoryx2, in
//! both directions, spoken in domain types.
//!
//! - [`grpc`]: [`ReplayClient`], the replay server's client for actors
//!   (streaming insert with acknowledgements, joining), the learner
//!   (sample, update priorities) and the CLI (table info, snapshots), on
//!   any host.
//! - [`shm`]: transition batches in iceoryx2 shared memory for actors on
//!   the replay server's host: the `#[repr(C)]` frame, both services (the
//!   replay server reads the frames) and [`ShmBatchPublisher`].
//! - [`iox`]: how both iceoryx2 frame services are opened, with the
//!   settings every side shares.
//! - [`wire`]: the replay's messages (transition batches, samples, table
//!   descriptions) between `crossroads_proto` and the domain, validating at
//!   the boundary.
//! - [`learner_client`]: [`LearnerClient`], the learner service's client
//!   (weights for actors; status, evaluations and checkpoints for the CLI).
//! - [`weights_shm`]: weights in iceoryx2 shared memory, the learner's
//!   publisher and the subscriber of actors on its host.
//! - [`weights_slot`]: [`WeightsSlot`], the newest
//!   [`Weights`](crossroads_types::Weights) a process holds: the learner's
//!   for its gRPC stream, an actor's for its network.
//! - [`security`]: TLS and the token of `[transport.tls]` and
//!   `[transport.auth]`, loaded once at start: [`ServerSecurity`] builds
//!   both tonic servers, [`ClientSecurity`] what every client needs;
//!   [`auth`] the token itself, the header clients send and the layer
//!   that refuses guarded calls without it; [`channel`] the one place a
//!   gRPC channel is built.
//! - [`convert`]: network specs, weights and checkpoint descriptions
//!   ([`CheckpointSummary`]) between `crossroads_proto` and the domain.
//!
//! Invariants the crate graph enforces: this crate links no tch (weights
//! travel as safetensors bytes whose metadata is read from the header
//! alone), so the replay server, which depends on it, has no libtorch; and
//! actors reach the learner through this crate, not through
//! `crossroads_learner` and its optimizer state. Public functions answer in
//! domain types (`crossroads_types` and the structs here); prost types
//! appear only in the conversions ([`wire`], [`convert`]), and outside this
//! crate only in `crossroads_proto` and the tonic services that implement
//! it.

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
