//! The `crossroads_actor_*` metrics: each is registered in
//! [`ActorMetrics::new`] with its labels (`scenario`, `mode`, `outcome`,
//! `transport` or `reason` where it has them) and a help text that says
//! what it counts. docs/roles.md, "Metrics of each role", lists them for
//! readers.

use prometheus::{
    Counter, Gauge, HistogramOpts, HistogramVec, IntCounter, IntCounterVec, IntGauge, Opts,
    Registry,
};

use crossroads_sim::EpisodeEnd;

/// Handles on the actor's metrics; cheap to clone (clones share values).
#[derive(Debug, Clone)]
pub struct ActorMetrics {
    scenario: String,
    env_steps: IntCounter,
    decisions: IntCounter,
    episodes: IntCounterVec,
    episode_duration: HistogramVec,
    episode_brake: HistogramVec,
    /// n-step transitions assembled.
    pub transitions_assembled: IntCounter,
    /// *Go*s the shield in the loop vetoed (`actor.shield`).
    pub shield_vetoes: IntCounter,
    /// Counterfactual *go*s run in forks and stored (`actor.go_forks`).
    pub go_forks: IntCounter,
    pushed: IntCounterVec,
    dropped: IntCounterVec,
    /// Batches waiting to be sent.
    pub buffer_batches: IntGauge,
    retries: IntCounterVec,
    latency: HistogramVec,
    /// Version of the weights in use (set by the weights subscriber).
    pub weights_version: IntGauge,
    /// Age of the weights in use, seconds (set by the weights subscriber).
    pub weights_staleness: Gauge,
    /// Exploration epsilon.
    pub epsilon: Gauge,
    /// Seconds the acting loop waited for a replay that was behind.
    pub backpressure_seconds: Counter,
    forward_passes: IntCounter,
    inference_seconds: Counter,
}

impl ActorMetrics {
    /// The metrics of an actor of `scenario`, registered in `registry`
    /// when given (unregistered handles otherwise, for tests and benches).
    pub fn new(registry: Option<&Registry>, scenario: &str) -> Result<Self, prometheus::Error> {
        let counter_vec = |name: &str, help: &str, labels: &[&str]| {
            IntCounterVec::new(Opts::new(name, help), labels)
        };
        let env_steps = counter_vec(
            "crossroads_actor_env_steps_total",
            "Simulation steps taken (0.2 s each)",
            &["scenario"],
        )?;
        let decisions = counter_vec(
            "crossroads_actor_decisions_total",
            "Actions taken (semi-MDP transitions, each one or more simulation steps)",
            &["scenario"],
        )?;
        let episodes = counter_vec(
            "crossroads_actor_episodes_total",
            "Episodes ended, by outcome",
            &["scenario", "mode", "outcome"],
        )?;
        let episode_duration = HistogramVec::new(
            HistogramOpts::new(
                "crossroads_actor_episode_duration_seconds",
                "Simulated time of an episode (the time to goal on success)",
            )
            .buckets(vec![2.0, 4.0, 6.0, 8.0, 10.0, 15.0, 20.0, 30.0, 45.0, 60.0]),
            &["scenario", "mode", "outcome"],
        )?;
        let episode_brake = HistogramVec::new(
            HistogramOpts::new(
                "crossroads_actor_episode_brake_seconds",
                "Braking time of traffic cars in an episode",
            )
            .buckets(vec![0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0]),
            &["scenario", "mode"],
        )?;
        let transitions_assembled = IntCounter::new(
            "crossroads_actor_transitions_assembled_total",
            "n-step transitions assembled",
        )?;
        let shield_vetoes = IntCounter::new(
            "crossroads_actor_shield_vetoes_total",
            "Go decisions the shield in the loop (actor.shield) vetoed and replaced",
        )?;
        let go_forks = IntCounter::new(
            "crossroads_actor_go_forks_total",
            "Counterfactual go decisions run in forks of the environment and stored (actor.go_forks)",
        )?;
        let pushed = counter_vec(
            "crossroads_actor_transitions_pushed_total",
            "Transitions acknowledged by the replay server",
            &["transport"],
        )?;
        let dropped = counter_vec(
            "crossroads_actor_transitions_dropped_total",
            "Transitions dropped: buffer_full (oldest dropped while the replay was unreachable) or rejected (refused by the replay)",
            &["reason"],
        )?;
        let buffer_batches = IntGauge::new(
            "crossroads_actor_push_buffer_batches",
            "Batches waiting to be sent to the replay server",
        )?;
        let retries = counter_vec(
            "crossroads_actor_push_retries_total",
            "Failed sends or connections to the replay server, each followed by a backoff",
            &["transport"],
        )?;
        let latency = HistogramVec::new(
            HistogramOpts::new(
                "crossroads_actor_push_latency_seconds",
                "Time from sending a batch to its acknowledgement",
            )
            .buckets(prometheus::exponential_buckets(0.0005, 2.0, 16)?),
            &["transport"],
        )?;
        let weights_version = IntGauge::new(
            "crossroads_actor_weights_version",
            "Version of the weights in use",
        )?;
        let weights_staleness = Gauge::new(
            "crossroads_actor_weights_staleness_seconds",
            "Age of the weights in use, from their publication",
        )?;
        let epsilon = Gauge::new(
            "crossroads_actor_epsilon",
            "Mean exploration epsilon over the environments (0 when greedy)",
        )?;
        let backpressure_seconds = Counter::new(
            "crossroads_actor_backpressure_seconds_total",
            "Seconds the acting loop waited for a live replay that was behind (its rate limiter)",
        )?;
        let forward_passes = IntCounter::new(
            "crossroads_actor_forward_passes_total",
            "Batched forward passes of the network (one per vectorized step)",
        )?;
        let inference_seconds = Counter::new(
            "crossroads_actor_inference_seconds_total",
            "Seconds spent in the network's forward passes",
        )?;
        if let Some(r) = registry {
            r.register(Box::new(forward_passes.clone()))?;
            r.register(Box::new(inference_seconds.clone()))?;
            r.register(Box::new(backpressure_seconds.clone()))?;
            r.register(Box::new(env_steps.clone()))?;
            r.register(Box::new(decisions.clone()))?;
            r.register(Box::new(episodes.clone()))?;
            r.register(Box::new(episode_duration.clone()))?;
            r.register(Box::new(episode_brake.clone()))?;
            r.register(Box::new(transitions_assembled.clone()))?;
            r.register(Box::new(shield_vetoes.clone()))?;
            r.register(Box::new(go_forks.clone()))?;
            r.register(Box::new(pushed.clone()))?;
            r.register(Box::new(dropped.clone()))?;
            r.register(Box::new(buffer_batches.clone()))?;
            r.register(Box::new(retries.clone()))?;
            r.register(Box::new(latency.clone()))?;
            r.register(Box::new(weights_version.clone()))?;
            r.register(Box::new(weights_staleness.clone()))?;
            r.register(Box::new(epsilon.clone()))?;
        }
        // Series that exist from the start, so dashboards show zeros.
        for reason in ["buffer_full", "rejected"] {
            dropped.with_label_values(&[reason]);
        }
        Ok(Self {
            env_steps: env_steps.with_label_values(&[scenario]),
            decisions: decisions.with_label_values(&[scenario]),
            scenario: scenario.to_owned(),
            episodes,
            episode_duration,
            episode_brake,
            transitions_assembled,
            shield_vetoes,
            go_forks,
            pushed,
            dropped,
            buffer_batches,
            retries,
            latency,
            weights_version,
            weights_staleness,
            epsilon,
            backpressure_seconds,
            forward_passes,
            inference_seconds,
        })
    }

    /// One forward pass of the network, of `seconds`.
    pub fn forward_pass(&self, seconds: f64) {
        self.forward_passes.inc();
        self.inference_seconds.inc_by(seconds);
    }

    /// Forward passes so far.
    pub fn forward_passes_total(&self) -> u64 {
        self.forward_passes.get()
    }

    /// Seconds in forward passes so far.
    pub fn inference_seconds_total(&self) -> f64 {
        self.inference_seconds.get()
    }

    /// The weights in use: their version and their age in seconds (from
    /// publication to now), for the weights subscriber.
    pub fn weights(&self, version: u64, age_s: f64) {
        self.weights_version
            .set(i64::try_from(version).unwrap_or(i64::MAX));
        self.weights_staleness.set(age_s.max(0.0));
    }

    /// Simulation steps and decisions taken.
    pub fn stepped(&self, sim_steps: u64, decisions: u64) {
        self.env_steps.inc_by(sim_steps);
        self.decisions.inc_by(decisions);
    }

    /// Simulation steps taken so far.
    pub fn env_steps_total(&self) -> u64 {
        self.env_steps.get()
    }

    /// An episode ended (`mode`: `train` or `eval`).
    pub fn episode(&self, mode: &str, end: &EpisodeEnd) {
        let outcome = outcome_label(end.outcome);
        let labels = [self.scenario.as_str(), mode, outcome];
        self.episodes.with_label_values(&labels).inc();
        self.episode_duration
            .with_label_values(&labels)
            .observe(end.time_s);
        self.episode_brake
            .with_label_values(&[self.scenario.as_str(), mode])
            .observe(end.brake_time_s);
    }

    /// Episodes ended with `outcome` in `mode`, so far.
    pub fn episodes(&self, mode: &str, outcome: crossroads_sim::Outcome) -> u64 {
        self.episodes
            .with_label_values(&[self.scenario.as_str(), mode, outcome_label(outcome)])
            .get()
    }

    /// Transitions acknowledged over `transport` (`grpc` or `shm`).
    pub fn pushed(&self, transport: &str, n: u64, latency_s: f64) {
        self.pushed.with_label_values(&[transport]).inc_by(n);
        self.latency
            .with_label_values(&[transport])
            .observe(latency_s);
    }

    /// Transitions acknowledged over `transport`, so far.
    pub fn pushed_total(&self, transport: &str) -> u64 {
        self.pushed.with_label_values(&[transport]).get()
    }

    /// Transitions dropped for `reason` (`buffer_full` or `rejected`).
    pub fn dropped(&self, reason: &str, n: u64) {
        self.dropped.with_label_values(&[reason]).inc_by(n);
    }

    /// Transitions dropped for `reason`, so far.
    pub fn dropped_total(&self, reason: &str) -> u64 {
        self.dropped.with_label_values(&[reason]).get()
    }

    /// A failed send or connection over `transport`.
    pub fn retry(&self, transport: &str) {
        self.retries.with_label_values(&[transport]).inc();
    }

    /// Failed sends or connections over `transport`, so far.
    pub fn retries_total(&self, transport: &str) -> u64 {
        self.retries.with_label_values(&[transport]).get()
    }
}

fn outcome_label(outcome: crossroads_sim::Outcome) -> &'static str {
    match outcome {
        crossroads_sim::Outcome::Success => "success",
        crossroads_sim::Outcome::Collision => "collision",
        crossroads_sim::Outcome::Timeout => "timeout",
    }
}
