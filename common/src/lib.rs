//! What every crossroads role shares: configuration, telemetry, metrics and
//! shutdown.
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

pub mod config;
pub mod metrics;
pub mod shutdown;
pub mod telemetry;

pub use config::{Config, ConfigError, ConfigLoader, ConfigProblem, LogFormat};
pub use metrics::MetricsServer;
pub use shutdown::Shutdown;
