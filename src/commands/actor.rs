//! `crossroads actor`: one actor process of a distributed run.

use std::process::ExitCode;

use anyhow::Context;
use crossroads_config::Config;
use crossroads_harness::role::{Role, block_on};

use crate::cli::ActorArgs;

/// Acts until SIGINT/SIGTERM (or `--max-steps`), pushing transitions to the
/// replay server and following the learner's weights.
pub fn run(config: &Config, args: &ActorArgs) -> anyhow::Result<ExitCode> {
    block_on(config, serve(config, args.max_steps))
}

async fn serve(config: &Config, max_steps: Option<u64>) -> anyhow::Result<()> {
    let role = Role::start(config, "actor").await?;
    let result = async {
        let actor = crossroads_actor::start_with_max_steps(
            config,
            Some(&role.registry),
            role.shutdown.clone(),
            max_steps,
        )
        .await
        .context("configuring the actor")?;
        actor.join().await.context("actor")?;
        Ok(())
    }
    .await;
    role.finish(result).await
}
