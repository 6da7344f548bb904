//! `crossroads learner`: the learner of a distributed run.

use std::process::ExitCode;

use anyhow::Context;
use crossroads_common::metrics::registry;
use crossroads_common::{Config, MetricsServer, Shutdown};

/// Trains until SIGINT/SIGTERM (or `learner.max_updates`), then writes the
/// last checkpoint.
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
    let mut shown = config.clone();
    shown.learner = config.learner.redacted();
    tracing::info!(config = %shown.to_toml(), "crossroads learner starting");
    let shutdown = Shutdown::on_signals().context("installing signal handlers")?;
    let registry = registry("learner")?;
    let learner = crossroads_learner::start(config, Some(&registry), shutdown.clone())
        .await
        .context("starting the learner")?;
    let metrics = if config.telemetry.metrics {
        match MetricsServer::start(config.telemetry.metrics_addr, registry, shutdown.clone()).await
        {
            Ok(m) => Some(m),
            Err(e) => {
                learner.stop();
                let _ = learner.join().await;
                return Err(e).context("starting the metrics endpoint");
            }
        }
    } else {
        None
    };
    let joined = learner.join().await.context("learner");
    // The learner also stops alone (max_updates, an error); the metrics
    // endpoint follows it.
    shutdown.trigger();
    if let Some(m) = metrics {
        m.join().await;
    }
    joined
}
