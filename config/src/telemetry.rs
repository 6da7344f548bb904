//! `[telemetry]`: logs and metrics.

use std::net::SocketAddr;

use serde::{Deserialize, Serialize};

/// How log lines are written to standard error.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// Human-readable lines.
    #[default]
    Text,
    /// One JSON object per line, for log collectors.
    Json,
}

/// Logs and metrics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TelemetryConfig {
    /// `text` or `json`. The level comes from `RUST_LOG` (default `info`).
    pub log_format: LogFormat,
    /// Whether the process serves Prometheus metrics.
    pub metrics: bool,
    /// Address of the `/metrics` endpoint; port 0 picks a free port.
    pub metrics_addr: SocketAddr,
}

impl Default for TelemetryConfig {
    fn default() -> Self {
        Self {
            log_format: LogFormat::Text,
            metrics: true,
            metrics_addr: SocketAddr::from(([127, 0, 0, 1], 9100)),
        }
    }
}
