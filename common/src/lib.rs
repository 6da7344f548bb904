//! What every crossroads role shares: configuration, telemetry, metrics,
//! shutdown and the transports that carry transition batches (the batches
//! themselves are `crossroads_types`).
//!
//! - [`config`]: the one TOML schema of a run ([`Config`], a section per
//!   concern) and its layered loading ([`ConfigLoader`]: defaults, file,
//!   `CROSSROADS_*` environment, command-line flags) with errors that name
//!   the origin, the key and the problem.
//! - [`telemetry`]: tracing to standard error, text or JSON, level from
//!   `RUST_LOG`.
//! - [`metrics`]: a Prometheus [`prometheus::Registry`] per process and the
//!   [`MetricsServer`] that serves it at `/metrics`.
//! - [`shutdown`]: the [`Shutdown`] signal (SIGINT, SIGTERM or a call) that
//!   every server and loop takes as an input.
//! - [`wire`]: conversion between `crossroads_proto` batches and the domain,
//!   validating at the boundary.
//! - [`transport`]: the replay server's gRPC client and the iceoryx2 batch
//!   publisher with its `#[repr(C)]` frame.
//! - [`retry`]: [`Backoff`], exponential with jitter.

pub mod config;
pub mod metrics;
pub mod retry;
pub mod shutdown;
pub mod telemetry;
pub mod transport;
pub mod wire;

pub use config::{
    ActorConfig, ActorTransport, Config, ConfigError, ConfigLoader, ConfigProblem, LearnerConfig,
    LogFormat, ReplayConfig, TrainConfig, TransportConfig, WeightNormalization,
};
pub use metrics::MetricsServer;
pub use retry::Backoff;
pub use shutdown::Shutdown;
