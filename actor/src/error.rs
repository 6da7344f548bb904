//! The error type of the crate.

use crossroads_transport::grpc::ClientError;
use crossroads_transport::shm::ShmError;

/// What can stop an actor. Network failures are not among them: the
/// pusher buffers and retries those.
#[derive(Debug, thiserror::Error)]
pub enum ActorError {
    /// The configuration does not describe a runnable actor.
    #[error("actor configuration: {0}")]
    Config(String),
    /// The scenario could not be loaded, or a step failed.
    #[error(transparent)]
    Sim(#[from] crossroads_sim::SimError),
    /// The Q-network failed or does not fit the environments.
    #[error("action values: {0}")]
    Values(String),
    /// The gRPC client could not be built (a bad endpoint, unreadable TLS
    /// files or token).
    #[error("replay client: {0}")]
    Client(#[from] ClientError),
    /// Shared memory could not be set up.
    #[error("shared memory: {0}")]
    Shm(#[from] ShmError),
    /// The actor's task or acting thread failed (panicked or was
    /// cancelled).
    #[error("{0}")]
    Task(String),
    /// A metric could not be registered.
    #[error("cannot register actor metrics: {0}")]
    Metrics(#[from] prometheus::Error),
}
