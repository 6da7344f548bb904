//! [`LearnerError`], what can stop the learner or fail one of its calls.

use crossroads_model::ModelError;
use crossroads_transport::SecurityError;
use crossroads_transport::grpc::ClientError;

use crate::checkpoint::StoreError;

/// Why the learner could not start, train or answer.
#[derive(Debug, thiserror::Error)]
pub enum LearnerError {
    /// The `[learner]` section does not describe a valid network.
    #[error("learner configuration: {0}")]
    Config(String),
    /// Building, running or loading the network failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A sampled batch does not fit the network (another observation kind
    /// or action set in the replay, NaN or infinite values).
    #[error("sampled batch does not fit the network: {0}")]
    Batch(String),
    /// The replay server refused a request it will always refuse.
    #[error("replay server: {0}")]
    Replay(#[from] ClientError),
    /// The loss became NaN or infinite; the update was not applied.
    #[error(
        "the loss is {loss} at update {step}; training diverged (lower learning_rate or check rewards)"
    )]
    Diverged {
        /// The update that produced it.
        step: u64,
        /// The loss.
        loss: f64,
    },
    /// A checkpoint could not be written, read or found.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// Checkpoints are off (`learner.checkpoint_dir` is not set).
    #[error("checkpoints are disabled: set learner.checkpoint_dir")]
    NoCheckpoints,
    /// Shared memory could not be set up.
    #[error("shared-memory weights: {0}")]
    Shm(String),
    /// The gRPC address could not be bound or the server failed.
    #[error("learner gRPC server: {0}")]
    Serve(String),
    /// The TLS files or the token cannot be used.
    #[error(transparent)]
    Security(#[from] SecurityError),
    /// A metric could not be registered.
    #[error("cannot register learner metrics: {0}")]
    Metrics(#[from] prometheus::Error),
    /// The training loop is gone (stopped or failed).
    #[error("the training loop has stopped")]
    Stopped,
    /// libtorch refused.
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
}
