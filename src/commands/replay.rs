//! `crossroads replay`: the prioritized replay server of a distributed run.

use std::process::ExitCode;

use anyhow::Context;
use crossroads_config::Config;
use crossroads_harness::role::{Role, announce, block_on};

/// Serves the replay table until SIGINT/SIGTERM, then writes the last
/// snapshot.
pub fn run(config: &Config) -> anyhow::Result<ExitCode> {
    block_on(config, serve(config))
}

async fn serve(config: &Config) -> anyhow::Result<()> {
    tracing::info!(config = %config.to_toml(), "crossroads replay starting");
    let role = Role::start(config, "replay").await?;
    let result = async {
        let server = crossroads_replay::start(config, Some(&role.registry), role.shutdown.clone())
            .await
            .context("starting the replay server")?;
        announce("listen", server.local_addr())?;
        server.join().await.context("replay server")
    }
    .await;
    role.finish(result).await
}
