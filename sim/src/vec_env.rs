//! M environments of one scenario stepped in parallel, their observations
//! as each one's non-zero values and, when asked for, in one contiguous
//! dense buffer, for one batched forward pass.

use std::sync::Arc;

use crossroads_types::ObservationLayout;
use crossroads_types::codec::{self, ObservationEncoding};
use rayon::prelude::*;

use crate::{Env, EnvConfig, ObsSpec, Outcome, Scenario, SimError, episode_seed};

/// How one episode ended, as the metrics and the log report it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpisodeEnd {
    /// Success, collision or timeout.
    pub outcome: Outcome,
    /// Simulation steps taken.
    pub steps: u32,
    /// Seconds driven (steps x dt); the time to goal on success.
    pub time_s: f64,
    /// Seconds of braking of traffic cars caused in the episode.
    pub brake_time_s: f64,
    /// The episode's seed (replays it with `Env::reset`).
    pub seed: u64,
}

/// What one environment did in one [`VecEnv::step`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnvStep {
    /// `sum_{i<k} gamma^i r_i` over the action's simulation steps.
    pub reward: f64,
    /// Simulation steps the action took, k.
    pub steps: u32,
    /// The episode ended; the environment has been reset since.
    pub done: bool,
    /// How it ended, when `done`.
    pub episode: Option<EpisodeEnd>,
}

#[derive(Debug)]
struct Slot {
    env: Env,
    /// Seed from which this environment's episode seeds derive.
    seed: u64,
    /// Episodes started.
    episodes: u64,
    /// Seed of the running episode.
    episode_seed: u64,
    /// The current observation, encoded (when encoding is on).
    encoded: Vec<u8>,
    /// The last observation of the episode that just ended, encoded.
    terminal: Vec<u8>,
}

/// M environments of one scenario and action set. Owns their current
/// observations: the simulators write each one's non-zero values
/// ([`VecEnv::sparse_observations`], a few dozen of a TTG grid's 2344),
/// and [`VecEnv::observations`] spreads them into one `M x obs_len` dense
/// buffer when a caller asks; [`VecEnv::step`] applies one action per environment in parallel on the
/// rayon pool and resets finished ones at once with fresh seeds: episode
/// `e` of environment `i` uses `episode_seed(episode_seed(seed, i), e)`,
/// so a run depends on the seed only, not on threads. Optionally encodes
/// each new observation (and each episode's last one) with the
/// observation codec, in the same parallel pass.
#[derive(Debug)]
pub struct VecEnv {
    scenario: Arc<Scenario>,
    config: EnvConfig,
    spec: ObsSpec,
    slots: Vec<Slot>,
    /// Each environment's current observation: its non-zero values in
    /// increasing index order.
    sparse: Vec<Vec<(u32, f32)>>,
    /// The same observations, `M x obs_len`, as of the last
    /// [`VecEnv::observations`] call; stale while `dense_fresh` is false.
    dense: Vec<f32>,
    dense_fresh: bool,
    results: Vec<EnvStep>,
    encoding: Option<ObservationEncoding>,
}

impl VecEnv {
    /// `envs` environments (at least 1) seeded from `seed`, reset and
    /// observed. `encoding` turns on encoding of observations (for
    /// transitions).
    pub fn new(
        scenario: Arc<Scenario>,
        config: EnvConfig,
        envs: usize,
        seed: u64,
        encoding: Option<ObservationEncoding>,
    ) -> Result<Self, SimError> {
        Self::with_range(scenario, config, 0..envs, seed, encoding)
    }

    /// Environments `range` of a [`VecEnv::new`] of `range.end`: its
    /// environment `k` is environment `range.start + k` there, with the same
    /// seeds (an actor's lanes split its environments this way).
    pub fn with_range(
        scenario: Arc<Scenario>,
        config: EnvConfig,
        range: std::ops::Range<usize>,
        seed: u64,
        encoding: Option<ObservationEncoding>,
    ) -> Result<Self, SimError> {
        if range.is_empty() {
            return Err(SimError::VecEnv(
                "at least one environment is needed".to_owned(),
            ));
        }
        let envs = range.len();
        let slots: Vec<Slot> = range
            .map(|i| Slot {
                env: Env::new(Arc::clone(&scenario), config),
                seed: episode_seed(seed, i as u64),
                episodes: 0,
                episode_seed: 0,
                encoded: Vec::new(),
                terminal: Vec::new(),
            })
            .collect();
        let spec = slots[0].env.obs_spec();
        let len = spec.len();
        let mut v = Self {
            scenario,
            config,
            spec,
            slots,
            sparse: vec![Vec::new(); envs],
            dense: vec![0.0; envs * len],
            dense_fresh: false,
            results: vec![EnvStep::default(); envs],
            encoding,
        };
        v.slots
            .par_iter_mut()
            .zip(v.sparse.par_iter_mut())
            .for_each(|(slot, out)| {
                slot.start_episode();
                slot.observe(out, encoding, len);
            });
        Ok(v)
    }

    /// Number of environments, M.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Never empty.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// Values in one observation.
    pub fn obs_len(&self) -> usize {
        self.spec.len()
    }

    /// The simulator's observation shape.
    pub fn obs_spec(&self) -> ObsSpec {
        self.spec
    }

    /// The observation layout transitions carry ([`ObsSpec::layout`]:
    /// kind `ttg`, `ttg-occlusion`, `sequential` or `sequential-occlusion`,
    /// the channel-major grid, then the ego features).
    pub fn layout(&self) -> ObservationLayout {
        self.spec.layout()
    }

    /// Size of the action set.
    pub fn num_actions(&self) -> usize {
        self.config.action_set.num_actions()
    }

    /// The environments' settings.
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// The scenario.
    pub fn scenario(&self) -> &Arc<Scenario> {
        &self.scenario
    }

    /// The current observations, `M x obs_len`, row `i` for environment
    /// `i`: spread from [`VecEnv::sparse_observations`] on the first call
    /// after a step (for a network that reads dense rows).
    pub fn observations(&mut self) -> &[f32] {
        if !self.dense_fresh {
            let len = self.spec.len();
            for (row, pairs) in self.dense.chunks_exact_mut(len).zip(&self.sparse) {
                // The simulators write indices inside their observation.
                let _ = codec::spread_pairs(pairs.iter().copied(), row);
            }
            self.dense_fresh = true;
        }
        &self.dense
    }

    /// The current observations, one per environment: each one's non-zero
    /// values as `(index, value)` in increasing index order.
    pub fn sparse_observations(&self) -> &[Vec<(u32, f32)>] {
        &self.sparse
    }

    /// Environment `i`.
    pub fn env(&self, i: usize) -> Option<&Env> {
        self.slots.get(i).map(|s| &s.env)
    }

    /// The current observation of environment `i`, encoded, taken out (the
    /// next call gives an empty vector until the next step); empty when
    /// encoding is off.
    pub fn take_encoded(&mut self, i: usize) -> Vec<u8> {
        self.slots
            .get_mut(i)
            .map(|s| std::mem::take(&mut s.encoded))
            .unwrap_or_default()
    }

    /// The last observation of the episode environment `i` finished in the
    /// last step, encoded, taken out.
    pub fn take_terminal(&mut self, i: usize) -> Vec<u8> {
        self.slots
            .get_mut(i)
            .map(|s| std::mem::take(&mut s.terminal))
            .unwrap_or_default()
    }

    /// What each environment did in the last [`VecEnv::step`] (defaults
    /// before the first).
    pub fn last_step(&self) -> &[EnvStep] {
        &self.results
    }

    /// Applies `actions[i]` to environment `i`, all in parallel; resets
    /// those whose episode ended. Returns what each did; the observations
    /// are the new ones (the first of a new episode where one ended).
    pub fn step(&mut self, actions: &[usize]) -> Result<&[EnvStep], SimError> {
        if actions.len() != self.slots.len() {
            return Err(SimError::VecEnv(format!(
                "{} actions for {} environments",
                actions.len(),
                self.slots.len()
            )));
        }
        let len = self.spec.len();
        let encoding = self.encoding;
        self.dense_fresh = false;
        self.slots
            .par_iter_mut()
            .zip(self.sparse.par_iter_mut())
            .zip(self.results.par_iter_mut())
            .zip(actions.par_iter())
            .try_for_each(|(((slot, out), result), &action)| {
                *result = slot.step(action, out, encoding, len)?;
                Ok::<_, SimError>(())
            })?;
        Ok(&self.results)
    }
}

impl Slot {
    fn start_episode(&mut self) {
        self.episode_seed = episode_seed(self.seed, self.episodes);
        self.episodes += 1;
        self.env.reset(self.episode_seed);
    }

    fn observe(
        &mut self,
        out: &mut Vec<(u32, f32)>,
        encoding: Option<ObservationEncoding>,
        len: usize,
    ) {
        self.env.write_observation_sparse(out);
        if let Some(encoding) = encoding {
            self.encoded.clear();
            codec::encode_pairs(encoding, out, len, &mut self.encoded);
        }
    }

    fn step(
        &mut self,
        action: usize,
        out: &mut Vec<(u32, f32)>,
        encoding: Option<ObservationEncoding>,
        len: usize,
    ) -> Result<EnvStep, SimError> {
        let r = self.env.step(action)?;
        let mut episode = None;
        if r.done {
            let m = self.env.metrics();
            episode = m.outcome.map(|outcome| EpisodeEnd {
                outcome,
                steps: m.steps,
                time_s: m.time_s,
                brake_time_s: m.brake_time_s,
                seed: self.episode_seed,
            });
            if let Some(encoding) = encoding {
                self.env.write_observation_sparse(out);
                self.terminal.clear();
                codec::encode_pairs(encoding, out, len, &mut self.terminal);
            }
            self.start_episode();
        }
        self.observe(out, encoding, len);
        Ok(EnvStep {
            reward: r.reward,
            steps: r.steps,
            done: r.done,
            episode,
        })
    }
}
