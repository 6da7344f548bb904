//! What every crossroads role shares at run time: telemetry, metrics,
//! shutdown and retry. The configuration schema is `crossroads_config`, the
//! domain types `crossroads_types`, the conversations between processes
//! `crossroads_transport`.
//!
//! - [`telemetry`]: tracing to standard error, text or JSON, level from
//!   `RUST_LOG`.
//! - [`metrics`]: a Prometheus [`prometheus::Registry`] per process and the
//!   [`MetricsServer`] that serves it at `/metrics`.
//! - [`shutdown`]: the [`Shutdown`] signal (SIGINT, SIGTERM or a call) that
//!   every server and loop takes as an input.
//! - [`retry`]: [`Backoff`], exponential with jitter.

pub mod metrics;
pub mod retry;
pub mod shutdown;
pub mod telemetry;

pub use metrics::MetricsServer;
pub use retry::Backoff;
pub use shutdown::Shutdown;
