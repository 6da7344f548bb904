//! What `crossroads replay`, `learner`, `actor` and `train` share: the
//! async runtime, signal handling, the process's metrics registry and its
//! `/metrics` endpoint.
//!
//! Each role's own flags are layered over its section before the
//! configuration loads (a key table per command, `crate::global::KeyFlag`);
//! the role's module in the binary then starts its crate's server or actor
//! and waits for a signal.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use crossroads_common::metrics::registry;
use crossroads_common::{MetricsServer, Shutdown};
use crossroads_config::Config;
use prometheus::Registry;

/// Runs `serve` on a multi-threaded runtime of `runtime.worker_threads`.
pub fn block_on(
    config: &Config,
    serve: impl Future<Output = anyhow::Result<()>>,
) -> anyhow::Result<ExitCode> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(config.runtime.worker_threads)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(serve)?;
    Ok(ExitCode::SUCCESS)
}

/// A role's process-wide parts: the shutdown signal (SIGINT/SIGTERM), the
/// metrics registry, and the `/metrics` endpoint when
/// `telemetry.metrics` is on. Must be made inside the runtime.
#[derive(Debug)]
pub struct Role {
    /// Fired by a signal or by [`finish`](Self::finish).
    pub shutdown: Shutdown,
    /// The registry the role's metrics go into.
    pub registry: Registry,
    endpoint: Option<MetricsServer>,
}

impl Role {
    /// Installs the signal handlers, makes the registry of `name` and
    /// serves it on `telemetry.metrics_addr`.
    pub async fn start(config: &Config, name: &str) -> anyhow::Result<Self> {
        let shutdown = Shutdown::on_signals().context("installing signal handlers")?;
        let registry = registry(name)?;
        let endpoint = if config.telemetry.metrics {
            let server = MetricsServer::start(
                config.telemetry.metrics_addr,
                registry.clone(),
                shutdown.clone(),
            )
            .await
            .context("starting the metrics endpoint")?;
            announce("metrics", server.local_addr())?;
            Some(server)
        } else {
            None
        };
        Ok(Self {
            shutdown,
            registry,
            endpoint,
        })
    }

    /// Stops what is left (the role may also end alone: an error, a step
    /// budget) and waits for the endpoint; returns `result`.
    pub async fn finish(self, result: anyhow::Result<()>) -> anyhow::Result<()> {
        self.shutdown.trigger();
        if let Some(m) = self.endpoint {
            m.join().await;
        }
        result
    }
}

/// The variable through which `crossroads train` asks a role it starts to
/// announce what it bound: a path prefix, one file per address.
pub const ANNOUNCE_VAR: &str = "CROSSROADS_ANNOUNCE";

/// The file under `prefix` that announces the address of `what`
/// (`metrics`, `listen`).
pub fn announced_path(prefix: &Path, what: &str) -> PathBuf {
    let mut path = prefix.as_os_str().to_owned();
    path.push(format!(".{what}"));
    PathBuf::from(path)
}

/// Writes `addr`, the address this role bound for `what`, where
/// [`ANNOUNCE_VAR`] asks (nothing when it is unset): whole or not at all,
/// through a temporary file renamed into place.
pub fn announce(what: &str, addr: SocketAddr) -> anyhow::Result<()> {
    let Some(prefix) = std::env::var_os(ANNOUNCE_VAR) else {
        return Ok(());
    };
    let path = announced_path(Path::new(&prefix), what);
    let tmp = announced_path(Path::new(&prefix), &format!("{what}.tmp"));
    std::fs::write(&tmp, addr.to_string())
        .with_context(|| format!("announcing {what} in {}", tmp.display()))?;
    std::fs::rename(&tmp, &path).with_context(|| format!("announcing {what} in {}", path.display()))
}
