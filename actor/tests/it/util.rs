//! Shared helpers: a linear Q-function, actors, replay servers.

use std::time::Duration;

use crossroads_actor::{ActionValues, Actor, ActorMetrics, ActorSettings, ValuesError};
use crossroads_config::TransportConfig;
use crossroads_config::{ActorConfig, Config, SimConfig};
use crossroads_types::TransitionBatch;

/// Q(s, a) = bias[a] + scale[a] * sum(s): cheap, deterministic, and
/// different per state, so priorities vary.
#[derive(Debug)]
pub struct LinearValues {
    pub obs_len: usize,
    pub bias: Vec<f32>,
    pub scale: Vec<f32>,
    pub calls: usize,
}

impl LinearValues {
    pub fn new(obs_len: usize, num_actions: usize) -> Self {
        Self {
            obs_len,
            bias: (0..num_actions).map(|a| 0.1 * a as f32).collect(),
            scale: (0..num_actions).map(|a| 0.01 * (a as f32 - 1.5)).collect(),
            calls: 0,
        }
    }
}

impl ActionValues for LinearValues {
    fn obs_len(&self) -> usize {
        self.obs_len
    }

    fn num_actions(&self) -> usize {
        self.bias.len()
    }

    fn q_values(&mut self, obs: &[f32], n: usize, out: &mut [f32]) -> Result<(), ValuesError> {
        self.calls += 1;
        let a = self.bias.len();
        for (row, q) in obs
            .chunks_exact(self.obs_len)
            .take(n)
            .zip(out.chunks_exact_mut(a))
        {
            let s: f32 = row.iter().sum();
            for (j, v) in q.iter_mut().enumerate() {
                *v = self.bias[j] + self.scale[j] * s;
            }
        }
        Ok(())
    }
}

pub fn actor_config(envs: usize, batch_size: usize) -> ActorConfig {
    ActorConfig {
        envs,
        batch_size,
        n_step: 3,
        ..ActorConfig::default()
    }
}

/// A training actor on left with TTG actions and a network for it.
pub fn actor(config: &ActorConfig, index: u32) -> (Actor, LinearValues) {
    actor_on(&SimConfig::default(), config, index)
}

/// A training actor of `sim`'s scenario and actions and a network for it.
pub fn actor_on(sim: &SimConfig, config: &ActorConfig, index: u32) -> (Actor, LinearValues) {
    let settings = ActorSettings::from_config(sim, config, index).expect("settings");
    let metrics = ActorMetrics::new(None, &sim.scenario).expect("metrics");
    let actor = Actor::new(settings, metrics).expect("actor");
    let values = LinearValues::new(actor.obs_len(), actor.num_actions());
    (actor, values)
}

/// Steps until `n` full batches are ready; returns them.
pub fn batches(actor: &mut Actor, values: &mut LinearValues, n: usize) -> Vec<TransitionBatch> {
    let mut out = Vec::new();
    for _ in 0..100_000 {
        actor.step(values).expect("step");
        while let Some(b) = actor.take_batch() {
            out.push(b);
        }
        if out.len() >= n {
            out.truncate(n);
            return out;
        }
    }
    panic!("no batches after 100000 steps");
}

/// A replay server config on `listen`, no snapshots, table "t".
pub fn replay_config(listen: &str, shm_prefix: Option<&str>) -> Config {
    let mut c = Config::default();
    c.replay.listen = listen.parse().expect("addr");
    c.replay.table = "t".to_owned();
    c.replay.capacity = 100_000;
    c.replay.min_size_to_sample = 1;
    c.replay.snapshot_dir = None;
    c.replay.snapshot_interval_secs = 0;
    c.replay.shm_ingest = shm_prefix.is_some();
    c.transport = transport(
        "http://127.0.0.1:1",
        shm_prefix.unwrap_or("crossroads-test"),
    );
    c
}

/// Short timeouts and backoffs, so failures show within a test.
pub fn transport(endpoint: &str, shm_prefix: &str) -> TransportConfig {
    TransportConfig {
        replay_endpoint: endpoint.to_owned(),
        connect_timeout_ms: 500,
        request_timeout_ms: 2_000,
        initial_backoff_ms: 20,
        max_backoff_ms: 300,
        shm_prefix: shm_prefix.to_owned(),
        shm_send_timeout_ms: 500,
        ..TransportConfig::default()
    }
}

/// A shared-memory prefix no other test or process uses.
pub fn unique_prefix(test: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!(
        "crossroads-test/actor-{test}/{}-{nanos}",
        std::process::id()
    )
}

/// Waits until `f` holds, at most `timeout`.
pub async fn eventually(timeout: Duration, what: &str, mut f: impl FnMut() -> bool) {
    let start = std::time::Instant::now();
    while !f() {
        assert!(start.elapsed() < timeout, "timed out waiting for {what}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}
