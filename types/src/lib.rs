//! The domain vocabulary of crossroads: the values every role and transport
//! speaks about, as plain Rust data.
//!
//! - [`batch`]: the [`TransitionBatch`] (struct-of-arrays n-step
//!   transitions over an [`ObservationPool`] that holds each observation
//!   once, with the [`ObservationLayout`] they have) and its validation,
//!   whose [`BatchError`] names the field; a
//!   [`ValidBatch`] is a batch that passed it.
//! - [`columns`]: [`Columns`], the six per-transition columns, written once
//!   for batches, replay tables, their snapshots and samples.
//! - [`sample`]: what a replay table answers ([`Sample`],
//!   [`PrioritiesUpdated`]), for the server and its clients alike.
//! - [`codec`]: the observation codec (dense f32 or sparse cells), the same
//!   bytes on gRPC and in shared memory.
//! - [`spec`]: what a Q-network is ([`NetworkSpec`]: the
//!   [`ObservationLayout`] it reads, the action set it scores, its
//!   [`TrunkKind`]).
//! - [`weights`]: one published version of the network ([`Weights`]) and
//!   the metadata of a weights file ([`WeightsMeta`]), read from the
//!   safetensors header without building a tensor.
//! - [`tensors`]: safetensors files of f32 tensors ([`F32Tensor`]) read
//!   and checked without a tensor library, for weights and optimizer
//!   state alike.
//! - [`checkpoint`]: which names a checkpoint may have, and its manifest
//!   ([`Manifest`]), checked against the checkpoint's files.
//!
//! Invariant, enforced by the crate graph: this crate depends on no tensor
//! library (tch), no RPC framework (tonic) and no wire format (prost), so
//! any crate can use the domain types without pulling those in; conversions
//! to the wire live in `crossroads_transport`, tensors in
//! `crossroads_model`.

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
pub use spec::{NetworkSpec, ObservationLayout, SpecError, TrunkKind, num_actions_of};
pub use tensors::F32Tensor;
pub use weights::{Weights, WeightsMeta};
