//! The domain vocabulary of crossroads: the values every role and transport
//! speaks about, as plain Rust data.
//!
//! - [`batch`]: the [`TransitionBatch`] (struct-of-arrays n-step
//!   transitions over an [`ObservationPool`] that holds each observation
//!   once, with their [`ObservationLayout`]), its validation, whose
//!   [`BatchError`] names the field, and [`ValidBatch`], a batch that passed.
//! - [`columns`]: [`Columns`], the six per-transition columns of batches,
//!   tables, snapshots and samples; [`sample`]: what a table answers
//!   ([`Sample`], [`PrioritiesUpdated`]); [`codec`]: the observation codec
//!   (dense f32 or sparse cells), the same bytes on gRPC and shared memory.
//! - [`spec`]: [`NetworkSpec`] (the layout a Q-network reads, the action
//!   set it scores, its [`TrunkKind`]); [`weights`]: [`Weights`] and the
//!   [`WeightsMeta`] of a safetensors header; [`tensors`]: f32 safetensors
//!   ([`F32Tensor`]); [`checkpoint`]: names and [`Manifest`]; no tensor
//!   library needed.
//!
//! No tch, tonic or prost (the crate graph enforces it): the wire is in
//! `crossroads_transport`, tensors in `crossroads_model`.

pub mod batch;
pub mod checkpoint;
pub mod codec;
pub mod columns;
pub mod sample;
pub mod spec;
pub mod tensors;
pub mod weights;

pub use batch::{
    BatchError, ObservationPool, RejectReason, Transition, TransitionBatch, ValidBatch,
};
pub use checkpoint::Manifest;
pub use codec::ObservationEncoding;
pub use columns::Columns;
pub use sample::{PrioritiesUpdated, Sample};
pub use spec::{
    NetworkSpec, ObservationLayout, SpecError, TrunkKind, absorbing_go_of, num_actions_of,
};
pub use tensors::F32Tensor;
pub use weights::{Weights, WeightsMeta};
