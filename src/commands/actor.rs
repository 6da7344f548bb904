//! `crossroads actor`: one actor process of a distributed run.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use crossroads_actor::{
    Actor, ActorMetrics, ActorSettings, LiveNetwork, Mode, PushConfig, Pusher,
    WeightsSubscription, resolve_index,
};
use crossroads_transport::WeightsSlot;
use crossroads_config::Config;
use crossroads_model::QNetwork;

use super::role::{Role, block_on};
use crate::cli::ActorArgs;

/// Longest wait at shutdown for buffered batches to reach the replay.
const DRAIN: Duration = Duration::from_secs(10);

/// Acts until SIGINT/SIGTERM (or `--max-steps`), pushing transitions to the
/// replay server and following the learner's weights.
pub fn run(config: &Config, args: &ActorArgs) -> anyhow::Result<ExitCode> {
    block_on(config, serve(config, args.max_steps))
}

async fn serve(config: &Config, max_steps: Option<u64>) -> anyhow::Result<()> {
    let ac = &config.actor;
    // A bad [actor] section fails before anything starts or waits.
    ActorSettings::from_config(ac, ac.index.unwrap_or(0)).context("configuring the actor")?;
    let role = Role::start(config, "actor").await?;
    let result = async {
        let Some(index) = resolve_index(
            ac.index,
            ac.count,
            ac.eval,
            &config.transport,
            &role.shutdown,
        )
        .await
        .context("finding this actor's index")?
        else {
            // SIGTERM while the replay server was not up yet: a clean stop.
            tracing::info!("actor stopped before it started acting");
            return Ok(());
        };
        let settings = ActorSettings::from_config(ac, index).context("configuring the actor")?;
        tracing::info!(
            index,
            count = settings.count,
            mode = ?settings.mode,
            envs = settings.envs,
            scenario = settings.scenario.name(),
            action_set = %settings.action_set,
            transport = ?ac.transport,
            weights = ?ac.weights_transport(),
            config = %config.to_toml(),
            "crossroads actor starting"
        );
        act(config, settings, &role, max_steps).await
    }
    .await;
    role.finish(result).await
}

async fn act(
    config: &Config,
    settings: ActorSettings,
    role: &Role,
    max_steps: Option<u64>,
) -> anyhow::Result<()> {
    let metrics = ActorMetrics::new(Some(&role.registry), settings.scenario.name())?;
    let spec = crossroads_learner::network_spec(&config.learner)
        .context("the [learner] network the actor starts from")?;
    let net = QNetwork::new(spec, config.learner.seed).context("building the first network")?;
    let slot = WeightsSlot::new();
    let subscription = WeightsSubscription::start(
        config.actor.weights_transport(),
        &config.transport,
        slot.clone(),
        &role.shutdown,
    )?;
    let training = settings.mode.is_training();
    let pusher = if training {
        Some(Pusher::start(
            &PushConfig::from_config(config),
            metrics.clone(),
            &role.shutdown,
        )?)
    } else {
        None
    };
    let mut actor = Actor::new(settings, metrics.clone())?;
    let mut live = LiveNetwork::new(net, &slot, metrics);
    let shutdown = role.shutdown.clone();
    let threads = config.runtime.compute_threads;
    let acting = tokio::task::spawn_blocking(move || {
        if threads > 0 {
            tch::set_num_threads(threads as i32);
        }
        let report = actor.run(&mut live, pusher.as_ref(), &shutdown, max_steps);
        (report, pusher, live.version(), actor.settings().mode)
    });
    let (report, pusher, version, mode) = acting.await.context("the acting thread")?;
    if let Some(p) = pusher {
        p.close(DRAIN).await;
    }
    subscription.stop().await;
    let report = report?;
    let e = &report.episodes;
    tracing::info!(
        steps = report.steps,
        sim_steps = report.sim_steps,
        transitions = report.transitions,
        episodes = e.episodes(),
        success_rate = e.success_rate(),
        collision_rate = e.collision_rate(),
        timeout_rate = e.timeout_rate(),
        mean_time_s = e.mean_success_time_s(),
        mean_brake_s = e.mean_brake_time_s(),
        weights_version = version,
        greedy = matches!(mode, Mode::Greedy),
        "actor stopped"
    );
    Ok(())
}
