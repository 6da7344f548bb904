//! The acting loop's core: one vectorized step at a time, from Q-values to
//! actions, environment steps, n-step transitions and batches.
//!
//! With `actor.pipeline` (at least 2 environments) the environments are two
//! lanes, and the calling thread computes one lane's Q-values and actions
//! while the rayon pool steps the other's simulators, so the forward pass
//! and the simulators overlap. Each environment keeps its seeds and random
//! streams either way. [`resolve_index`] takes `actor.index`, or asks the
//! replay server for one by host name (`JoinActor`), modulo `actor.count`.

use std::collections::VecDeque;
use std::ops::Range;
use std::sync::Arc;

use crossroads_common::Shutdown;
use crossroads_common::retry::Backoff;
use crossroads_config::{ActorConfig, SimConfig, TransportConfig};
use crossroads_sim::{
    ActionSet, EnvConfig, EpisodeEnd, Intent, Policy, PolicyRng, PolicySpec, Scenario, SensedCar,
    ShieldParams, VecEnv, check_go, episode_seed, sense, shield_fallback, splitmix64,
};
use crossroads_transport::grpc::ReplayClient;
use crossroads_types::TransitionBatch;
use crossroads_types::codec::ObservationEncoding;
use rand::{RngExt, SeedableRng};

use crate::error::ActorError;
use crate::exploration::{AbsorbingGo, EpsilonGreedy, Intents, Ladder, Mode};
use crate::metrics::ActorMetrics;
use crate::nstep::{BatchBuilder, EncodedObs, NStepAssembler, NStepTransition, ObsRef};
use crate::push::Pusher;
use crate::stats::EpisodeStats;
use crate::values::{ActionValues, argmax};

/// Everything an [`Actor`] needs, resolved from the config.
#[derive(Debug, Clone)]
pub struct ActorSettings {
    /// The scenario, compiled.
    pub scenario: Arc<Scenario>,
    /// The action set.
    pub action_set: ActionSet,
    /// Environments, M.
    pub envs: usize,
    /// Decisions per n-step transition.
    pub n_step: usize,
    /// Discount per simulation step.
    pub gamma: f64,
    /// Collision reward replacing the scenario's, if set.
    pub collision_reward: Option<f64>,
    /// Transitions per batch.
    pub batch_size: usize,
    /// This actor's index i and the actor count N.
    pub index: u32,
    /// The actor count N.
    pub count: u32,
    /// This actor's seed (derived from the run's seed and the index).
    pub seed: u64,
    /// Exploration or greedy evaluation.
    pub mode: Mode,
    /// Explore an absorbing *go* once per episode (see [`EpsilonGreedy`]).
    pub explore_go_once: bool,
    /// Explore by intents held this many decisions on average
    /// (`actor.explore_intents`, [`Intents`]); `None` when off.
    pub intent_hold: Option<f64>,
    /// Cut n-step windows before exploratory actions.
    pub cut_at_exploration: bool,
    /// Act on the environments in two lanes, one lane's forward pass
    /// beside the other's simulation step (see [`Actor`]).
    pub pipeline: bool,
    /// Environments that follow a rule early in training
    /// (`actor.early_demo_envs`); `None` when none do or when evaluating.
    pub demonstrations: Option<Demonstrations>,
    /// The shield every environment acts through (`actor.shield`).
    pub shield: Option<ActorShield>,
    /// Counterfactual *go* labels (`actor.go_forks`); `None` when off or
    /// evaluating.
    pub go_forks: Option<GoForks>,
}

/// Counterfactual *go* labels (`actor.go_forks`): at a training decision
/// that is not a *go*, with probability `share`, a fork of the environment
/// runs the final *go* to its end, and that *go* is stored from the
/// decision's observation with the fork's return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoForks {
    /// Probability per decision that is not a *go*.
    pub share: f64,
    /// The action set's final *go*.
    pub go: usize,
}

impl GoForks {
    /// From `actor.go_forks`; `None` when 0 or evaluating; an error naming
    /// the key when the action set has no final *go*.
    fn from_config(
        config: &ActorConfig,
        action_set: ActionSet,
    ) -> Result<Option<Self>, ActorError> {
        if config.eval || config.go_forks <= 0.0 {
            return Ok(None);
        }
        if !(0.0..=1.0).contains(&config.go_forks) {
            return Err(ActorError::Config(format!(
                "actor.go_forks must be in [0, 1], got {}",
                config.go_forks
            )));
        }
        let go = action_set
            .final_go_for("actor.go_forks", "it forks a final go")
            .map_err(|e| ActorError::Config(format!("actor.go_forks: {e}")))?;
        Ok(Some(Self {
            share: config.go_forks,
            go,
        }))
    }
}

/// `actor.intent_hold` where `actor.explore_intents` is on; an error naming
/// the key where the action set has no creep to encode (TTG). The hold's
/// range is the config's check (`ActorConfig::validate`).
fn intent_hold_of(config: &ActorConfig, action_set: ActionSet) -> Result<Option<f64>, ActorError> {
    if !config.explore_intents {
        return Ok(None);
    }
    if action_set.encode(Intent::Creep, 0.0, 1.0).is_none() {
        return Err(ActorError::Config(format!(
            "actor.explore_intents: {} actions cannot creep; use creep or sequential actions",
            action_set.name()
        )));
    }
    Ok(Some(config.intent_hold))
}

/// The safety shield in the acting loop (`actor.shield`,
/// `actor.veto_cost`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActorShield {
    /// Its assumptions.
    pub params: ShieldParams,
    /// Subtracted from the reward of a vetoed *go*'s own transition.
    pub veto_cost: f32,
}

impl ActorShield {
    /// From `actor.shield` and `actor.veto_cost`; `None` when unset; an
    /// error naming `actor.shield` when its assumptions do not parse or the
    /// action set has no final *go* to check.
    fn from_config(
        config: &ActorConfig,
        action_set: ActionSet,
    ) -> Result<Option<Self>, ActorError> {
        let Some(spec) = config.shield.as_deref() else {
            return Ok(None);
        };
        let params = ShieldParams::parse(spec)
            .map_err(|e| ActorError::Config(format!("actor.shield: {e}")))?;
        action_set
            .final_go_for("the shield", "it checks a final go")
            .map_err(|e| ActorError::Config(format!("actor.shield: {e}")))?;
        Ok(Some(Self {
            params,
            veto_cost: config.veto_cost as f32,
        }))
    }
}

/// Demonstrations (`actor.early_demo_envs`, `actor.demo_policy`,
/// `actor.early_demo_steps`): environments `first..` of the actor follow
/// `policy` instead of the network during the actor's first `steps` steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Demonstrations {
    /// The rule.
    pub policy: PolicySpec,
    /// The first demonstrating environment; every one after it demonstrates.
    pub first: usize,
    /// Steps of the actor during which they do.
    pub steps: u64,
}

impl Demonstrations {
    /// From `[actor]`, for `action_set`: `None` when no environment
    /// demonstrates; an error naming the key when the rule cannot be read
    /// or cannot drive the action set.
    fn from_config(
        config: &ActorConfig,
        action_set: ActionSet,
    ) -> Result<Option<Self>, ActorError> {
        let envs = config.envs.max(1);
        if config.eval || config.early_demo_envs == 0 {
            return Ok(None);
        }
        let text = config.demo_policy.as_deref().ok_or_else(|| {
            ActorError::Config(
                "actor.demo_policy is needed when actor.early_demo_envs is set".to_owned(),
            )
        })?;
        let policy: PolicySpec = text
            .parse()
            .map_err(|e| ActorError::Config(format!("actor.demo_policy: {e}")))?;
        if matches!(policy, PolicySpec::Random | PolicySpec::Never) {
            return Err(ActorError::Config(format!(
                "actor.demo_policy: {text} demonstrates nothing; use ttc:<seconds> or ttc-creep:<seconds>"
            )));
        }
        if matches!(policy, PolicySpec::Go) {
            return Err(ActorError::Config(format!(
                "actor.demo_policy: {text} goes at once, looking at nothing; use ttc:<seconds> \
                 or ttc-creep:<seconds>"
            )));
        }
        if matches!(policy, PolicySpec::Oracle(_)) {
            return Err(ActorError::Config(format!(
                "actor.demo_policy: {text} sees cars behind the walls; its demonstrations would \
                 teach going blind. Use ttc:<seconds> or ttc-creep:<seconds>"
            )));
        }
        policy
            .build()
            .supports(action_set)
            .map_err(|e| ActorError::Config(format!("actor.demo_policy: {e}")))?;
        if config.early_demo_envs > envs {
            return Err(ActorError::Config(format!(
                "actor.early_demo_envs {} is above actor.envs {envs}",
                config.early_demo_envs
            )));
        }
        Ok(Some(Self {
            policy,
            first: envs - config.early_demo_envs,
            steps: config.early_demo_steps,
        }))
    }
}

/// `[sim]`'s scenario, compiled, and its action set.
fn load_sim(sim: &SimConfig) -> Result<(Arc<Scenario>, ActionSet), ActorError> {
    let scenario = Arc::new(Scenario::load_with_drivers(
        &sim.scenario,
        sim.drivers.as_deref(),
    )?);
    let action_set: ActionSet = sim
        .action_set
        .parse()
        .map_err(|e: crossroads_sim::SimError| {
            ActorError::Config(format!("sim.action_set: {e}"))
        })?;
    Ok((scenario, action_set))
}

/// Fills `sim.observation` and its layout with the observation actors of
/// `[sim]`'s scenario and action set produce (the paper's pairing: the
/// Sequential grid for Sequential actions, the TTG grid otherwise,
/// occlusion channels when the scenario has occluders), or checks that the
/// one given is a view of the simulator and that one. Every role resolves
/// it at start, so the learner's network reads what the actors send; the
/// layout comes from the simulator (no environment is built).
pub fn resolve_observation(sim: &mut SimConfig) -> Result<(), ActorError> {
    if let Some(given) = sim.observation()
        && let Err(e) = crossroads_sim::observation_layout(given)
    {
        return Err(ActorError::Config(format!("sim.observation: {e}")));
    }
    let (scenario, action_set) = load_sim(sim)?;
    let produced = EnvConfig::for_actions(action_set)
        .observation
        .spec(scenario.occlusion_channels())
        .layout();
    sim.resolve_layout(produced).map_err(ActorError::Config)
}

impl ActorSettings {
    /// From `[sim]` and `[actor]`, for actor `index` (see
    /// [`resolve_index`]).
    pub fn from_config(
        sim: &SimConfig,
        config: &ActorConfig,
        index: u32,
    ) -> Result<Self, ActorError> {
        let (scenario, action_set) = load_sim(sim)?;
        let count = config.count.max(1);
        if index >= count {
            return Err(ActorError::Config(format!(
                "actor index {index} is not below actor.count {count}"
            )));
        }
        let mode = if config.eval {
            Mode::Greedy
        } else {
            let rungs = if config.ladder_over_envs {
                Ladder::new
            } else {
                Ladder::per_actor
            };
            Mode::Explore {
                ladder: rungs(
                    config.epsilon_base,
                    config.epsilon_alpha,
                    index,
                    count,
                    config.envs.max(1) as u32,
                ),
            }
        };
        let demonstrations = Demonstrations::from_config(config, action_set)?;
        let shield = ActorShield::from_config(config, action_set)?;
        let go_forks = GoForks::from_config(config, action_set)?;
        let intent_hold = intent_hold_of(config, action_set)?;
        Ok(Self {
            scenario,
            action_set,
            envs: config.envs.max(1),
            n_step: config.n_step.max(1) as usize,
            gamma: config.gamma,
            collision_reward: config.collision_reward,
            batch_size: config.batch_size.max(1),
            index,
            count,
            seed: actor_seed(config.seed, index),
            mode,
            explore_go_once: config.explore_go_once,
            intent_hold,
            cut_at_exploration: config.cut_at_exploration,
            pipeline: config.pipeline,
            demonstrations,
            shield,
            go_forks,
        })
    }
}

/// The seed of actor `index` in a run seeded `run_seed`.
pub fn actor_seed(run_seed: u64, index: u32) -> u64 {
    episode_seed(splitmix64(run_seed ^ 0xAC70_0000), u64::from(index))
}

/// This actor's index among `count`: `configured` when set; else, for a
/// training actor, the index the replay server at `connection` hands out to
/// this host's name (`JoinActor`: in order of first request, the same again
/// for the same name, so a restarted container keeps its place), modulo
/// `count`; an evaluating actor that has none uses 0 and takes no place on
/// the ladder. Waits, retrying with backoff, while the replay server is not
/// up yet: `None` when `shutdown` fires meanwhile, an error when the server
/// refuses the name.
pub async fn resolve_index(
    configured: Option<u32>,
    count: u32,
    eval: bool,
    connection: &TransportConfig,
    shutdown: &Shutdown,
) -> Result<Option<u32>, ActorError> {
    if let Some(i) = configured {
        return Ok(Some(i));
    }
    if eval {
        return Ok(Some(0));
    }
    let name = hostname().unwrap_or_else(|| format!("pid-{}", std::process::id()));
    let client = ReplayClient::new(connection, "")?;
    let mut backoff = Backoff::from_config(connection);
    loop {
        let attempt = tokio::select! {
            r = client.join_actor(&name) => r,
            () = shutdown.wait() => return Ok(None),
        };
        match attempt {
            Ok(joined) => {
                let index = joined.index % count.max(1);
                tracing::info!(
                    %name,
                    joined = joined.index,
                    index,
                    count,
                    "index from the replay server"
                );
                return Ok(Some(index));
            }
            Err(e) if e.is_retryable() => {
                if backoff.attempts().is_multiple_of(10) {
                    tracing::warn!(
                        endpoint = %connection.replay_endpoint,
                        error = %e,
                        "waiting for the replay server to hand out an index"
                    );
                }
                tokio::select! {
                    () = backoff.wait() => {}
                    () = shutdown.wait() => {}
                }
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// The host name, from `HOSTNAME` or `/etc/hostname`.
pub fn hostname() -> Option<String> {
    std::env::var("HOSTNAME")
        .ok()
        .filter(|h| !h.is_empty())
        .or_else(|| {
            std::fs::read_to_string("/etc/hostname")
                .ok()
                .map(|h| h.trim().to_owned())
                .filter(|h| !h.is_empty())
        })
}

/// What an [`Actor::run`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunReport {
    /// Vectorized steps (forward passes).
    pub steps: u64,
    /// Simulation steps, summed over environments.
    pub sim_steps: u64,
    /// Transitions assembled (all handed to the pusher).
    pub transitions: u64,
    /// The episodes that ended.
    pub episodes: EpisodeStats,
}

/// What one [`Actor::step`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepSummary {
    /// Simulation steps taken, summed over environments.
    pub sim_steps: u64,
    /// Decisions taken (one per environment).
    pub decisions: u64,
    /// Transitions assembled.
    pub transitions: u64,
    /// Episodes that ended.
    pub episodes: Vec<EpisodeEnd>,
}

/// An actor's environments, exploration and n-step assembly. Each
/// [`step`](Self::step) takes one decision and one simulation action per
/// environment: batched forward passes of the caller's [`ActionValues`]
/// (so the caller may swap weights between steps), epsilon-greedy actions
/// and parallel environment steps; in training mode full batches of
/// transitions queue up for [`take_batch`](Self::take_batch). Not
/// thread-safe; one per acting loop.
///
/// With `pipeline` (and at least 2 environments) the environments are two
/// lanes of halves: the calling thread computes one lane's Q-values while
/// the rayon pool steps the other lane's simulators, so neither the forward
/// pass nor the simulators wait for the other. The second lane's actions
/// of one call are chosen at the end of the call before (from its
/// observations then), so each call is: lane 2 steps / lane 1 decides,
/// lane 1 steps / lane 2 decides. Every environment still sees its own
/// seeds and random streams; only which weights version a lane acts with
/// may differ by one update.
#[derive(Debug)]
pub struct Actor {
    settings: ActorSettings,
    lanes: Vec<Lane>,
    builder: BatchBuilder,
    ready: VecDeque<TransitionBatch>,
    metrics: ActorMetrics,
    /// Greedy episodes since the last evaluation summary in the log.
    eval_tally: (std::time::Instant, EpisodeStats),
    /// Steps taken, for the demonstrations' end.
    steps: u64,
}

/// A contiguous range of an actor's environments and everything kept per
/// environment: exploration streams, n-step windows, the Q-values and
/// actions of its last decision.
#[derive(Debug)]
struct Lane {
    envs: VecEnv,
    explorer: EpsilonGreedy,
    assemblers: Vec<NStepAssembler>,
    current: Vec<Option<ObsRef>>,
    q: Vec<f32>,
    actions: Vec<usize>,
    episode_steps: Vec<u32>,
    /// Each ego's speed at the decision (for exploring intents).
    speeds: Vec<f64>,
    emitted: Vec<NStepTransition>,
    /// `actions` are chosen and not yet applied.
    decided: bool,
    /// The next observation id; ids step by the number of lanes, so no two
    /// lanes hand out the same one.
    next_obs_id: u64,
    id_stride: u64,
    /// This lane's demonstrating environments, if any.
    demo: Option<LaneDemo>,
    /// The shield the lane acts through, if any.
    shield: Option<ActorShield>,
    /// Cars the shield sensed (scratch).
    sensed: Vec<SensedCar>,
    /// Per environment, the *go* the shield vetoed at the last decision
    /// (training), to be stored beside the executed action.
    vetoed: Vec<Option<VetoedGo>>,
    /// *Go*s vetoed since the counter was last read.
    vetoes: u64,
    /// Counterfactual *go* labels, with their random stream.
    forks: Option<(GoForks, PolicyRng)>,
    /// *Go*s run in forks since the counter was last read.
    forked: u64,
}

/// A *go* the shield replaced, waiting for the executed step's outcome.
#[derive(Debug)]
struct VetoedGo {
    observation: ObsRef,
    action: u32,
    /// Initial priority: |Q(fallback) - veto_cost - Q(go)|, the TD error
    /// with the fallback's own estimate as its target.
    priority: f32,
}

/// The rule a lane's demonstrating environments follow, which of them
/// (indices in the lane) and one random stream each.
#[derive(Debug)]
struct LaneDemo {
    policy: Box<dyn Policy>,
    envs: Range<usize>,
    rngs: Vec<PolicyRng>,
}

/// How often an evaluating actor logs its running outcome rates.
const EVAL_LOG_EVERY: std::time::Duration = std::time::Duration::from_secs(30);

impl Actor {
    /// An actor with its environments reset.
    pub fn new(settings: ActorSettings, metrics: ActorMetrics) -> Result<Self, ActorError> {
        let mut env_config = EnvConfig::for_actions(settings.action_set);
        env_config.gamma = settings.gamma;
        env_config.collision_reward = settings.collision_reward;
        let m = settings.envs.max(1);
        // Where the lanes start and end: two halves, or one lane of all.
        let bounds = if settings.pipeline && m >= 2 {
            vec![0, m / 2, m]
        } else {
            vec![0, m]
        };
        let n = bounds.len() as u64 - 1;
        let lanes = bounds
            .windows(2)
            .enumerate()
            .map(|(k, w)| Lane::new(&settings, env_config, w[0]..w[1], (k as u64, n)))
            .collect::<Result<Vec<_>, _>>()?;
        let lane = &lanes[0].envs;
        let builder = BatchBuilder::new(
            lane.layout(),
            lane.num_actions() as u32,
            ObservationEncoding::SparseF32,
        );
        metrics.epsilon.set(settings.mode.epsilon());
        Ok(Self {
            lanes,
            builder,
            ready: VecDeque::new(),
            metrics,
            eval_tally: (std::time::Instant::now(), EpisodeStats::default()),
            steps: 0,
            settings,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &ActorSettings {
        &self.settings
    }

    /// Values in one observation.
    pub fn obs_len(&self) -> usize {
        self.lanes[0].envs.obs_len()
    }

    /// Size of the action set.
    pub fn num_actions(&self) -> usize {
        self.lanes[0].envs.num_actions()
    }

    /// Lanes the environments are acted on in (2 when pipelined).
    pub fn lanes(&self) -> usize {
        self.lanes.len()
    }

    /// The metrics handles.
    pub fn metrics(&self) -> &ActorMetrics {
        &self.metrics
    }

    /// One vectorized step: every environment's Q-values (one call of
    /// `values` per lane), epsilon-greedy actions, parallel environment
    /// steps, n-step transitions (training mode).
    pub fn step(&mut self, values: &mut dyn ActionValues) -> Result<StepSummary, ActorError> {
        let (obs_len, a) = (self.obs_len(), self.num_actions());
        if values.obs_len() != obs_len || values.num_actions() != a {
            return Err(ActorError::Values(format!(
                "the network reads {} values and scores {} actions; the environments give {} ({}) and take {} ({})",
                values.obs_len(),
                values.num_actions(),
                obs_len,
                self.lanes[0].envs.layout(),
                a,
                self.settings.action_set
            )));
        }
        let training = self.settings.mode.is_training();
        let cut = training && self.settings.cut_at_exploration;
        let demonstrating = training
            && self
                .settings
                .demonstrations
                .is_some_and(|d| self.steps < d.steps);
        self.steps += 1;
        if demonstrating
            && let Some(d) = self.settings.demonstrations
            && self.steps == d.steps
        {
            tracing::info!(
                policy = %d.policy,
                environments = self.settings.envs - d.first,
                steps = d.steps,
                "demonstrations end; every environment explores from now on"
            );
        }
        let how = Decide {
            training,
            cut,
            demonstrating,
        };
        let mut done = Recorded {
            training,
            gamma: self.settings.gamma,
            mode: if training { "train" } else { "eval" },
            scenario: self.settings.scenario.name(),
            metrics: &self.metrics,
            eval_tally: &mut self.eval_tally.1,
            summary: StepSummary::default(),
        };
        match self.lanes.as_mut_slice() {
            [lane] => {
                lane.decide(values, how)?;
                lane.apply()?;
                lane.record(&mut done);
            }
            [first, second] => {
                if !second.decided {
                    second.decide(values, how)?;
                }
                let mut stepped = Ok(());
                rayon::in_place_scope(|s| {
                    s.spawn(|_| stepped = second.apply());
                    first.decide(values, how)
                })?;
                stepped?;
                let mut stepped = Ok(());
                rayon::in_place_scope(|s| {
                    s.spawn(|_| stepped = first.apply());
                    second.record(&mut done);
                    second.decide(values, how)
                })?;
                stepped?;
                first.record(&mut done);
            }
            _ => unreachable!("an actor has one or two lanes"),
        }
        let mut summary = done.summary;
        for lane in &mut self.lanes {
            self.metrics
                .shield_vetoes
                .inc_by(std::mem::take(&mut lane.vetoes));
            self.metrics
                .go_forks
                .inc_by(std::mem::take(&mut lane.forked));
            summary.transitions += lane.emitted.len() as u64;
            for t in lane.emitted.drain(..) {
                self.builder.push(&t);
                if self.builder.len() >= self.settings.batch_size {
                    self.ready.push_back(self.builder.take());
                }
            }
        }
        self.metrics.stepped(summary.sim_steps, summary.decisions);
        self.metrics
            .transitions_assembled
            .inc_by(summary.transitions);
        if !training && self.eval_tally.0.elapsed() >= EVAL_LOG_EVERY {
            self.log_evaluation();
        }
        Ok(summary)
    }

    /// Logs the greedy episodes' outcome rates since the last summary (each
    /// episode is a debug line; at info an evaluator would log thousands a
    /// second).
    fn log_evaluation(&mut self) {
        let (since, tally) = std::mem::replace(
            &mut self.eval_tally,
            (std::time::Instant::now(), EpisodeStats::default()),
        );
        if tally.episodes() > 0 {
            tracing::info!(
                scenario = self.settings.scenario.name(),
                episodes = tally.episodes(),
                seconds = since.elapsed().as_secs_f64().round(),
                success = tally.success_rate(),
                collision = tally.collision_rate(),
                timeout = tally.timeout_rate(),
                mean_time_s = tally.mean_success_time_s(),
                "greedy evaluation"
            );
        }
    }

    /// Steps until `shutdown` fires (or `max_steps` steps), handing every
    /// full batch to `pusher` (when training), then the partial one.
    /// Blocking: run it on a thread of its own (`spawn_blocking`). The
    /// network is the caller's: an implementation that applies newer
    /// weights at the start of `q_values` picks them up between steps
    /// without pausing the environments.
    pub fn run(
        &mut self,
        values: &mut dyn ActionValues,
        pusher: Option<&Pusher>,
        shutdown: &Shutdown,
        max_steps: Option<u64>,
    ) -> Result<RunReport, ActorError> {
        let mut report = RunReport::default();
        while !shutdown.is_triggered() && max_steps.is_none_or(|m| report.steps < m) {
            let summary = self.step(values)?;
            report.steps += 1;
            report.sim_steps += summary.sim_steps;
            report.transitions += summary.transitions;
            summary
                .episodes
                .iter()
                .for_each(|e| report.episodes.record(e));
            while let Some(batch) = self.take_batch() {
                if let Some(p) = pusher {
                    p.push(batch);
                }
            }
            if let Some(p) = pusher {
                self.wait_while_backlogged(p, shutdown);
            }
        }
        if let (Some(p), Some(batch)) = (pusher, self.flush_batch()) {
            p.push(batch);
        }
        Ok(report)
    }

    /// Back-pressure: while a live replay is behind (see
    /// [`Pusher::backlogged`]), waits instead of acting, and counts the
    /// time.
    fn wait_while_backlogged(&self, pusher: &Pusher, shutdown: &Shutdown) {
        while pusher.backlogged() && !shutdown.is_triggered() {
            let start = std::time::Instant::now();
            std::thread::sleep(std::time::Duration::from_millis(1));
            self.metrics
                .backpressure_seconds
                .inc_by(start.elapsed().as_secs_f64());
        }
    }

    /// A full batch, oldest first, if one is ready.
    pub fn take_batch(&mut self) -> Option<TransitionBatch> {
        self.ready.pop_front()
    }

    /// Whatever is collected, full or not (at shutdown); `None` when
    /// nothing is.
    pub fn flush_batch(&mut self) -> Option<TransitionBatch> {
        if let Some(b) = self.ready.pop_front() {
            return Some(b);
        }
        (!self.builder.is_empty()).then(|| self.builder.take())
    }
}

/// How a step's decisions are taken: training (n-step windows), cutting
/// windows before exploratory actions, with demonstrations.
#[derive(Debug, Clone, Copy)]
struct Decide {
    training: bool,
    cut: bool,
    demonstrating: bool,
}

/// Where a lane's finished steps are counted: the step's summary, the
/// episode metrics, the evaluation tally.
struct Recorded<'a> {
    training: bool,
    /// Discount per simulation step.
    gamma: f64,
    mode: &'static str,
    scenario: &'a str,
    metrics: &'a ActorMetrics,
    eval_tally: &'a mut EpisodeStats,
    summary: StepSummary,
}

impl Lane {
    /// Environments `range` of the actor `settings` describe, reset (and
    /// their first observations interned when training); lane `k` of `n`.
    fn new(
        settings: &ActorSettings,
        env_config: EnvConfig,
        range: Range<usize>,
        (k, n): (u64, u64),
    ) -> Result<Self, ActorError> {
        let training = settings.mode.is_training();
        let envs = VecEnv::with_range(
            Arc::clone(&settings.scenario),
            env_config,
            range.clone(),
            settings.seed,
            training.then_some(ObservationEncoding::SparseF32),
        )?;
        let mut explorer = EpsilonGreedy::for_range(settings.mode, range.clone(), settings.seed);
        if let Some(action) = settings
            .action_set
            .absorbing_go()
            .filter(|_| settings.explore_go_once)
        {
            explorer = explorer.with_absorbing_go(AbsorbingGo {
                action,
                step_limit: settings.scenario.spec().step_limit,
            });
        }
        if let Some(mean_hold) = settings.intent_hold {
            explorer = explorer.with_intents(Intents {
                set: settings.action_set,
                creep_speed: settings.scenario.spec().ego.params.creep_speed,
                mean_hold,
            });
        }
        let m = envs.len();
        let demo = settings.demonstrations.and_then(|d| {
            let envs = d.first.max(range.start)..range.end;
            (!envs.is_empty()).then(|| LaneDemo {
                policy: d.policy.build(),
                rngs: envs
                    .clone()
                    .map(|i| {
                        PolicyRng::seed_from_u64(episode_seed(settings.seed ^ 0xDE30, i as u64))
                    })
                    .collect(),
                envs: envs.start - range.start..envs.end - range.start,
            })
        });
        let mut lane = Self {
            explorer,
            assemblers: vec![NStepAssembler::new(settings.n_step, settings.gamma); m],
            current: vec![None; m],
            q: vec![0.0; m * envs.num_actions()],
            actions: vec![0; m],
            episode_steps: vec![0; m],
            speeds: vec![0.0; m],
            emitted: Vec::new(),
            decided: false,
            next_obs_id: k,
            id_stride: n,
            demo,
            shield: settings.shield,
            sensed: Vec::new(),
            vetoed: (0..m).map(|_| None).collect(),
            vetoes: 0,
            forks: settings.go_forks.map(|f| {
                (
                    f,
                    PolicyRng::seed_from_u64(episode_seed(settings.seed ^ 0xF02C, k)),
                )
            }),
            forked: 0,
            envs,
        };
        if training {
            for i in 0..m {
                lane.current[i] = Some(lane.intern(i, false));
            }
        }
        Ok(lane)
    }

    /// Q-values of the current observations in one call of `values`, then
    /// one epsilon-greedy action per environment, or the rule's for the
    /// demonstrating ones (`demonstrating`); opens n-step windows (training)
    /// and cuts them before exploratory actions and the rule's actions that
    /// are not greedy (`cut`).
    fn decide(&mut self, values: &mut dyn ActionValues, how: Decide) -> Result<(), ActorError> {
        let Decide {
            training,
            cut,
            demonstrating,
        } = how;
        let m = self.envs.len();
        let a = self.envs.num_actions();
        if values.reads_sparse() {
            values.q_values_sparse(self.envs.sparse_observations(), &mut self.q)
        } else {
            values.q_values(self.envs.observations(), m, &mut self.q)
        }
        .map_err(|e| ActorError::Values(e.to_string()))?;
        if training {
            for i in 0..m {
                if let Some(obs) = self.current[i].take() {
                    self.assemblers[i].begin(obs, &self.q[i * a..(i + 1) * a], &mut self.emitted);
                }
            }
        }
        for i in 0..m {
            let env = self.envs.env(i);
            self.episode_steps[i] = env.map_or(0, crossroads_sim::Env::steps);
            self.speeds[i] = env.map_or(0.0, |e| e.ego().v);
        }
        self.explorer.choose(
            &self.q,
            a,
            &self.episode_steps,
            &self.speeds,
            &mut self.actions,
        );
        let demo = self.demo.as_mut().filter(|_| demonstrating);
        let shown = demo.as_ref().map_or(0..0, |d| d.envs.clone());
        if let Some(d) = demo {
            for (k, i) in d.envs.clone().enumerate() {
                let env = self.envs.env(i).expect("a lane's environment");
                d.policy.act(
                    std::slice::from_ref(env),
                    &mut d.rngs[k..=k],
                    &mut self.actions[i..=i],
                )?;
            }
        }
        if self.shield.is_some() {
            self.shield_decisions(training);
        }
        if training && self.forks.is_some() {
            self.fork_gos()?;
        }
        if cut {
            // n-step returns follow the greedy policy: a window ends
            // (bootstrapping) before an exploratory action or a rule's
            // action the network would not take.
            for i in 0..m {
                let greedy = if shown.contains(&i) {
                    self.actions[i] == argmax(&self.q[i * a..(i + 1) * a])
                } else {
                    self.explorer.was_greedy(i)
                };
                if !greedy {
                    self.assemblers[i].cut(&mut self.emitted);
                }
            }
        }
        self.decided = true;
        Ok(())
    }

    /// The shield's checks of this decision's *go*s: a vetoed one becomes
    /// the network's best one-step alternative; when training, it is kept
    /// (with the observation decided on, its n-step window's current one)
    /// to be stored beside the executed action.
    fn shield_decisions(&mut self, training: bool) {
        let Some(shield) = self.shield else { return };
        let a = self.envs.num_actions();
        for i in 0..self.envs.len() {
            let env = self.envs.env(i).expect("a lane's environment");
            let Some(go) = env.config().action_set.absorbing_go() else {
                return;
            };
            if self.actions[i] != go || env.ego().committed {
                continue;
            }
            sense(env, &shield.params, &mut self.sensed);
            if check_go(env, &self.sensed, &shield.params).is_none() {
                continue;
            }
            let q = &self.q[i * a..(i + 1) * a];
            let fallback = shield_fallback(env, go, Some(q));
            self.actions[i] = fallback;
            self.vetoes += 1;
            let decided_on = training
                .then(|| self.assemblers[i].current_observation().cloned())
                .flatten();
            if let Some(observation) = decided_on {
                let td = (q[fallback] - shield.veto_cost - q[go]).abs();
                self.vetoed[i] = Some(VetoedGo {
                    observation,
                    action: go as u32,
                    priority: if td.is_finite() {
                        td
                    } else {
                        crate::nstep::FALLBACK_PRIORITY
                    },
                });
            }
        }
    }

    /// Counterfactual *go* labels (`actor.go_forks`): where this decision
    /// is not a *go*, now and then a fork of the environment runs the *go*
    /// to its end, and the *go* is stored from the decision's observation
    /// with the fork's return. The transition ends the episode (discount
    /// 0), so its next observation is never read; the decision's own
    /// stands in for it.
    fn fork_gos(&mut self) -> Result<(), ActorError> {
        let Some((forks, rng)) = self.forks.as_mut() else {
            return Ok(());
        };
        let a = self.envs.num_actions();
        let go = forks.go;
        for i in 0..self.envs.len() {
            if !rng.random_bool(forks.share) {
                continue;
            }
            let env = self.envs.env(i).expect("a lane's environment");
            if self.actions[i] == go || env.ego().committed || env.is_done() {
                continue;
            }
            let Some(observation) = self.assemblers[i].current_observation().cloned() else {
                continue;
            };
            let mut fork = env.fork(rng.random());
            let end = fork.step(go)?;
            let reward = end.reward as f32;
            let td = (reward - self.q[i * a + go]).abs();
            self.emitted.push(NStepTransition {
                observation: Arc::clone(&observation),
                action: go as u32,
                reward,
                discount: 0.0,
                priority: if td.is_finite() {
                    td
                } else {
                    crate::nstep::FALLBACK_PRIORITY
                },
                next_observation: observation,
            });
            self.forked += 1;
        }
        Ok(())
    }

    /// Steps every environment with its chosen action (on the rayon pool).
    fn apply(&mut self) -> Result<(), ActorError> {
        self.envs.step(&self.actions)?;
        self.decided = false;
        Ok(())
    }

    /// Counts the last [`Lane::apply`] into `done` and, when training,
    /// records each environment's step in its n-step window.
    fn record(&mut self, done: &mut Recorded<'_>) {
        let a = self.envs.num_actions();
        let m = self.envs.len();
        done.summary.decisions += m as u64;
        for i in 0..m {
            let r = self.envs.last_step()[i];
            done.summary.sim_steps += u64::from(r.steps);
            if let Some(end) = r.episode {
                done.metrics.episode(done.mode, &end);
                tracing::debug!(scenario = done.scenario, mode = done.mode, outcome = ?end.outcome, time_s = end.time_s, brake_s = end.brake_time_s, seed = end.seed, "episode");
                if !done.training {
                    done.eval_tally.record(&end);
                }
                done.summary.episodes.push(end);
            }
            if done.training {
                let action = self.actions[i];
                let terminal = r.done.then(|| self.intern(i, true));
                let vetoed = self.vetoed[i].take();
                let after = terminal.clone();
                self.assemblers[i].record(
                    action as u32,
                    self.q[i * a + action],
                    r.reward,
                    r.steps,
                    terminal,
                    &mut self.emitted,
                );
                let next = self.intern(i, false);
                if let Some(v) = vetoed {
                    // The shielded task's go: the executed step's outcome,
                    // less the cost.
                    let (next_observation, discount) = match after {
                        Some(last) => (last, 0.0),
                        None => (Arc::clone(&next), done.gamma.powi(r.steps as i32) as f32),
                    };
                    let cost = self.shield.map_or(0.0, |s| s.veto_cost);
                    self.emitted.push(NStepTransition {
                        observation: v.observation,
                        action: v.action,
                        reward: r.reward as f32 - cost,
                        discount,
                        priority: v.priority,
                        next_observation,
                    });
                }
                self.current[i] = Some(next);
            }
        }
    }

    fn intern(&mut self, i: usize, terminal: bool) -> ObsRef {
        let bytes = if terminal {
            self.envs.take_terminal(i)
        } else {
            self.envs.take_encoded(i)
        };
        let id = self.next_obs_id;
        self.next_obs_id += self.id_stride;
        Arc::new(EncodedObs { id, bytes })
    }
}
