//! `crossroads learner`: the learner of a distributed run.

use std::process::ExitCode;

use anyhow::Context;
use crossroads_config::Config;
use crossroads_harness::role::{Role, announce, block_on};

/// Trains until SIGINT/SIGTERM (or `learner.max_updates`), then writes the
/// last checkpoint.
pub fn run(config: &Config) -> anyhow::Result<ExitCode> {
    block_on(config, serve(config))
}

async fn serve(config: &Config) -> anyhow::Result<()> {
    tracing::info!(config = %config.to_toml(), "crossroads learner starting");
    let role = Role::start(config, "learner").await?;
    let result = async {
        let learner =
            crossroads_learner::start(config, Some(&role.registry), role.shutdown.clone())
                .await
                .context("starting the learner")?;
        announce("listen", learner.local_addr())?;
        // The learner also stops alone (max_updates, an error); the
        // metrics endpoint follows it.
        learner.join().await.context("learner")
    }
    .await;
    role.finish(result).await
}
