//! Protobuf schema and gRPC services of crossroads, package `crossroads.v1`.
//!
//! Generated at build time from `proto/crossroads/v1/*.proto` by prost and
//! tonic: `schema.proto` holds the data messages (transition batches,
//! observation pools, weights, checkpoint descriptions), `replay.proto` the
//! [`v1::replay_server::Replay`] service and `learner.proto` the
//! [`v1::learner_server::Learner`] service. This is the only crate with prost
//! types; every other crate converts them into its own types at its boundary.
//! Every service and client uses [`codec::Codec`], under which bytes that
//! do not decode as the expected message answer INVALID_ARGUMENT.

pub mod codec;

/// Messages and services of package `crossroads.v1`.
pub mod v1 {
    #![allow(missing_debug_implementations, unused_qualifications, clippy::all)]
    tonic::include_proto!("crossroads.v1");
}
