//! [`ModelError`], what can go wrong building, running or loading a network.

use tch::Kind;

use crossroads_types::{NetworkSpec, SpecError};

/// Why a network could not be built, run or loaded.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A dimension, observation kind, action set or trunk is invalid.
    #[error("invalid network spec: {0}")]
    Spec(String),
    /// The input does not have the expected shape.
    #[error("expected input of shape [batch, {expected}], got {got:?}")]
    Shape {
        /// Features the network expects.
        expected: i64,
        /// Shape it got.
        got: Vec<i64>,
    },
    /// A sparse observation names a value beyond the observation's length.
    #[error("observation {row} has a value at index {index}, beyond its {width} values")]
    Index {
        /// Row in the batch.
        row: usize,
        /// The index given.
        index: usize,
        /// Values in an observation.
        width: usize,
    },
    /// The input is not f32.
    #[error("expected f32 input, got {0:?}")]
    Kind(Kind),
    /// NaN or infinite values where finite ones are needed.
    #[error("{0} holds NaN or infinite values")]
    NonFinite(String),
    /// Weights of another network.
    #[error("weights are for another network: expected {expected:?}, got {got:?}")]
    SpecMismatch {
        /// This network's spec.
        expected: Box<NetworkSpec>,
        /// The weights' spec.
        got: Box<NetworkSpec>,
    },
    /// The bytes are not valid weights of this format.
    #[error("invalid weights file: {0}")]
    Format(String),
    /// The device `runtime.device` asks for is not there (the message names
    /// what is missing).
    #[error("{0}")]
    Device(String),
    /// libtorch refused.
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
}

impl From<SpecError> for ModelError {
    fn from(e: SpecError) -> Self {
        match e {
            SpecError::Invalid(message) => ModelError::Spec(message),
            SpecError::Format(message) => ModelError::Format(message),
        }
    }
}
