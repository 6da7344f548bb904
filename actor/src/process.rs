//! Starting and stopping an actor process: its index, environments, first
//! network, weights subscription, pusher and acting thread, all under one
//! [`Shutdown`].
//!
//! [`start`] checks the `[actor]` section and returns a [`RunningActor`]
//! at once; in the background the actor finds its index (asking the replay
//! server when the configuration has none, waiting while it is not up),
//! assembles its [`ActorParts`], subscribes to the learner's weights and
//! acts on a blocking thread. [`RunningActor::join`] waits for the stop: on
//! shutdown (or after its step budget) the acting thread hands over its
//! last partial batch, the pusher drains for at most [`DRAIN`] and the
//! subscription ends.

use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_config::Config;
use crossroads_model::{Precision, QNetwork, Work, network_spec};
use crossroads_transport::WeightsSlot;
use prometheus::Registry;
use tokio::task::JoinHandle;

use crate::actor::{Actor, ActorSettings, RunReport, resolve_index};
use crate::error::ActorError;
use crate::exploration::Mode;
use crate::metrics::ActorMetrics;
use crate::push::{PushConfig, Pusher};
use crate::weights::{LiveNetwork, WeightsSubscription};

/// Longest wait at shutdown for buffered batches to reach the replay.
pub const DRAIN: Duration = Duration::from_secs(10);

/// An actor assembled from the configuration, before it acts: its
/// [`Actor`] (environments reset), the [`LiveNetwork`] it acts with (the
/// network `[learner]` describes, built with `learner.seed`, following
/// `weights`) and the slot newer weights go into.
#[derive(Debug)]
pub struct ActorParts {
    /// Environments, exploration and n-step assembly.
    pub actor: Actor,
    /// The network, applying the newest version in `weights` between steps.
    pub network: LiveNetwork,
    /// Where a [`WeightsSubscription`] puts the learner's weights.
    pub weights: WeightsSlot,
}

impl ActorParts {
    /// Actor `index` of the run `config` describes, reporting to `metrics`.
    pub fn new(config: &Config, index: u32, metrics: ActorMetrics) -> Result<Self, ActorError> {
        let mut settings = ActorSettings::from_config(&config.sim, &config.actor, index)?;
        let spec = network_spec(&config.sim, &config.learner).map_err(|e| {
            ActorError::Config(format!("the [learner] network the actor starts from: {e}"))
        })?;
        let mut net = QNetwork::new(spec, config.learner.seed)
            .map_err(|e| ActorError::Values(format!("building the first network: {e}")))?;
        let precision = Precision::choose(config.runtime.precision, net.spec(), Work::Acting);
        net.set_precision(precision);
        tracing::info!(%precision, "actor network number format");
        let weights = WeightsSlot::new();
        let network = LiveNetwork::new(net, &weights, metrics.clone())?;
        // Two lanes pay where the forward pass is cheap beside the
        // simulators (plain Rust); a libtorch pass (conv) costs more at half
        // the batch than the overlap saves.
        settings.pipeline &= network.is_native();
        Ok(Self {
            actor: Actor::new(settings, metrics)?,
            network,
            weights,
        })
    }
}

/// A started actor.
#[derive(Debug)]
pub struct RunningActor {
    metrics: ActorMetrics,
    stop: Shutdown,
    task: JoinHandle<Result<Option<RunReport>, ActorError>>,
}

impl RunningActor {
    /// The actor's metrics.
    pub fn metrics(&self) -> &ActorMetrics {
        &self.metrics
    }

    /// Stops this actor alone (the shutdown given to [`start`] also stops
    /// it).
    pub fn stop(&self) {
        self.stop.trigger();
    }

    /// Waits until the actor has stopped and drained its pusher; returns
    /// what it did, `None` when it stopped before it had an index, or the
    /// error that stopped it.
    pub async fn join(self) -> Result<Option<RunReport>, ActorError> {
        let joined = self.task.await;
        joined.unwrap_or_else(|e| Err(ActorError::Task(format!("actor task failed: {e}"))))
    }
}

/// Starts the actor `config.actor` describes, pushing to
/// `config.transport.replay_endpoint` and following the learner's weights,
/// with its metrics in `registry` when given; it acts until `shutdown`.
/// Fails at once on an `[actor]` section that cannot run. Must be called
/// inside a multi-threaded tokio runtime.
pub async fn start(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
) -> Result<RunningActor, ActorError> {
    start_with_max_steps(config, registry, shutdown, None).await
}

/// [`start`], stopping alone after `max_steps` vectorized steps when
/// given.
pub async fn start_with_max_steps(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
    max_steps: Option<u64>,
) -> Result<RunningActor, ActorError> {
    let ac = &config.actor;
    // A bad [sim] or [actor] section fails before anything waits.
    let settings = ActorSettings::from_config(&config.sim, ac, ac.index.unwrap_or(0))?;
    let metrics = ActorMetrics::new(registry, settings.scenario.name())?;
    let stop = shutdown.child();
    let task = tokio::spawn(act(
        config.clone(),
        metrics.clone(),
        stop.clone(),
        max_steps,
    ));
    Ok(RunningActor {
        metrics,
        stop,
        task,
    })
}

/// Runs the actor until `shutdown` fires.
pub async fn run(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
) -> Result<(), ActorError> {
    start(config, registry, shutdown).await?.join().await?;
    Ok(())
}

async fn act(
    config: Config,
    metrics: ActorMetrics,
    shutdown: Shutdown,
    max_steps: Option<u64>,
) -> Result<Option<RunReport>, ActorError> {
    let ac = &config.actor;
    let Some(index) =
        resolve_index(ac.index, ac.count, ac.eval, &config.transport, &shutdown).await?
    else {
        // Stopped while the replay server was not up yet: a clean stop.
        tracing::info!("actor stopped before it started acting");
        return Ok(None);
    };
    let ActorParts {
        mut actor,
        mut network,
        weights,
    } = ActorParts::new(&config, index, metrics.clone())?;
    let settings = actor.settings();
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
    let subscription = WeightsSubscription::start(
        ac.weights_transport(),
        &config.transport,
        weights,
        &shutdown,
    )?;
    let pusher = if settings.mode.is_training() {
        Some(Pusher::start(
            &PushConfig::from_config(&config),
            metrics,
            &shutdown,
        )?)
    } else {
        None
    };
    let threads = config.runtime.torch_threads();
    let acting = tokio::task::spawn_blocking(move || {
        if let Some(n) = threads {
            tch::set_num_threads(n as i32);
        }
        let report = actor.run(&mut network, pusher.as_ref(), &shutdown, max_steps);
        (report, pusher, network.version(), actor.settings().mode)
    });
    let joined = acting.await;
    let (report, pusher, version, mode) =
        joined.map_err(|e| ActorError::Task(format!("the acting thread: {e}")))?;
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
    Ok(Some(report))
}
