//! The dueling Q-network, in tch, shared by actors (batched inference) and
//! the learner (training), and its weights format.
//!
//! A [`NetworkSpec`] says what a network is: the [`ObservationLayout`] it
//! reads (a channel-major grid plus dense features, as the simulator
//! gives it; this crate knows no sizes of its own), the
//! action set it scores and its trunk ([`TrunkKind::Mlp`] or
//! [`TrunkKind::Conv`]); it and the weights metadata ([`WeightsMeta`]) are
//! tch-free and live in `crossroads_types`, re-exported here. [`QNetwork`] builds it with value V(s) and
//! advantage A(s, a) heads combined as Q = V + A - mean(A) (Wang et al.
//! 2016); [`QNetwork::infer`] is the batched inference actors call, and
//! [`QNetwork::q_values`] the differentiable forward pass the learner trains;
//! both read [`Observations`], sparse where the trunk's first layer can
//! skip the zeros of a TTG observation (an MLP's: an embedding bag over its
//! transposed weight). A network computes its trunk in a [`Precision`]:
//! fp32, or bf16 over fp32 master weights where the CPU has matrix units
//! for it. [`NativeMlp`] is an MLP's forward pass in plain Rust over a copy
//! of its weights, for the actor's small batches.
//! [`weights`] is the on-disk and on-wire format: safetensors with the spec
//! and a version number in its metadata, readable by Python's safetensors
//! and PyTorch. [`network_spec`] is the network a run's `[sim]` and
//! `[learner]` sections describe. Networks are built on the CPU;
//! [`QNetwork::new_on`] moves one to the device [`resolve_device`] picks
//! for `runtime.device` (the learner's; actors stay on the CPU).

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
    self as spec, NetworkSpec, ObservationLayout, SpecError, TrunkKind, num_actions_of,
};
pub use device::{CudaSupport, device_name, resolve_device};
pub use error::ModelError;
pub use native::NativeMlp;
pub use network::{QBatch, QNetwork};
pub use observations::{Observations, SparseRows};
pub use precision::{Precision, Work, cpu_has_amx_bf16};
pub use weights::WeightsMeta;
