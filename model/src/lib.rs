//! The dueling Q-network, in tch, shared by actors (batched inference) and
//! the learner (training), and its weights format.
//!
//! A [`NetworkSpec`] says what a network is: the [`ObservationLayout`] it
//! reads (this crate knows no sizes of its own), the action set it scores
//! and its trunk ([`TrunkKind::Mlp`] or [`TrunkKind::Conv`]); it and
//! [`WeightsMeta`] are tch-free, re-exported from `crossroads_types`.
//! [`QNetwork`] combines value and advantage heads as Q = V + A - mean(A)
//! (Wang et al. 2016); [`QNetwork::infer`] is the actors' batched inference
//! and [`QNetwork::q_values`] the learner's differentiable forward pass,
//! both over [`Observations`], sparse where the first layer can skip a TTG
//! observation's zeros (an MLP's: an embedding bag over its transposed
//! weight). The trunk computes in a [`Precision`] (fp32, or bf16 over fp32
//! master weights); [`NativeMlp`] is an MLP's forward pass in plain Rust for
//! the actor's small batches. [`weights`] is the on-disk and on-wire format
//! (safetensors with spec and version in its metadata, readable by PyTorch).
//! [`network_spec`] is the network of a run's `[sim]` and `[learner]`;
//! networks are built on the CPU, and [`QNetwork::new_on`] moves one to the
//! device [`resolve_device`] picks for `runtime.device` (the learner's).

mod config;
mod device;
mod error;
mod native;
mod network;
mod observations;
mod precision;
pub mod weights;

pub use config::network_spec;
pub use crossroads_types::spec::{
    self as spec, NetworkSpec, ObservationLayout, SpecError, TrunkKind, absorbing_go_of,
    num_actions_of,
};
pub use device::{CudaSupport, device_name, resolve_device};
pub use error::ModelError;
pub use native::NativeMlp;
pub use network::{QBatch, QNetwork};
pub use observations::{Observations, SparseRows};
pub use precision::{Precision, Work, cpu_has_amx_bf16};
pub use weights::WeightsMeta;
