//! What every crossroads role shares: configuration, telemetry, metrics,
//! shutdown and retry. The domain types are `crossroads_types`; the
//! conversations between processes `crossroads_transport`.
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
//! - [`retry`]: [`Backoff`], exponential with jitter.

pub mod config;
pub mod metrics;
pub mod retry;
pub mod shutdown;
pub mod telemetry;

pub use config::{
    ActorConfig, ActorTransport, Config, ConfigError, ConfigLoader, ConfigProblem, LearnerConfig,
    LogFormat, ReplayConfig, TrainConfig, TransportConfig, WeightNormalization,
};
pub use metrics::MetricsServer;
pub use retry::Backoff;
pub use shutdown::Shutdown;
