//! `crossroads replay`: the prioritized replay server of a distributed run.

use std::process::ExitCode;

use anyhow::Context;
use crossroads_common::metrics::registry;
use crossroads_common::{Config, MetricsServer, Shutdown};

/// Serves the replay table until SIGINT/SIGTERM, then writes the last
/// snapshot.
pub fn run(config: &Config) -> anyhow::Result<ExitCode> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(config.runtime.worker_threads)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(serve(config))?;
    Ok(ExitCode::SUCCESS)
}

async fn serve(config: &Config) -> anyhow::Result<()> {
    tracing::info!(config = %config.to_toml(), "crossroads replay starting");
    let shutdown = Shutdown::on_signals().context("installing signal handlers")?;
    let registry = registry("replay")?;
    let server = crossroads_replay::start(config, Some(&registry), shutdown.clone())
        .await
        .context("starting the replay server")?;
    let metrics = if config.telemetry.metrics {
        match MetricsServer::start(config.telemetry.metrics_addr, registry, shutdown.clone()).await
        {
            Ok(m) => Some(m),
            Err(e) => {
                shutdown.trigger();
                let _ = server.join().await;
                return Err(e).context("starting the metrics endpoint");
            }
        }
    } else {
        None
    };
    let joined = server.join().await.context("replay server");
    if let Some(m) = metrics {
        m.join().await;
    }
    joined
}
