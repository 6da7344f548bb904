//! How transitions and calls travel between roles.
//!
//! - [`grpc`]: [`ReplayClient`](grpc::ReplayClient), the replay server's
//!   client for actors (streaming insert with acknowledgements) and the
//!   learner (sample, update priorities), on any host.
//! - [`shm`]: [`ShmBatchPublisher`](shm::ShmBatchPublisher) and the
//!   `#[repr(C)]` frame of a batch in iceoryx2 shared memory, for actors on
//!   the replay server's host.

pub mod grpc;
pub mod shm;
