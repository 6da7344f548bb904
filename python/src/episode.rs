//! What the Python classes share, without Python: the environment that a
//! scenario, an action set, a driver preset and overrides make
//! ([`Settings`]), its seeding, the observation's bounds, and writing an
//! observation into a caller's row.
//!
//! Seeding is `crossroads eval`'s: after a reset with base seed `s`,
//! episode `e` is reset with `episode_seed(s, e)`, so it is trial `e` of
//! `crossroads eval --seed s`.

use std::sync::Arc;

use crossroads_sim::{
    ActionSet, DriverPopulation, Env, EnvConfig, ObsKind, ObsSpec, Outcome, Scenario, ScenarioSpec,
    SimError, StepResult, episode_seed,
};

/// How to build an environment, as the Python face's arguments give it.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// A built-in scenario's name or a scenario TOML file.
    pub scenario: String,
    /// The action set.
    pub actions: ActionSet,
    /// A driver preset or drivers TOML file; `None` keeps the scenario's.
    pub drivers: Option<String>,
    /// The grid (`None`: the action set's, as the paper pairs them).
    pub observation: Option<ObsKind>,
    /// Discount of the rewards inside a k-step action.
    pub gamma: f64,
    /// Reward of a collision in place of the scenario's.
    pub collision_reward: Option<f64>,
    /// A JSON object merged into the scenario's spec, table by table
    /// (e.g. `{"emission_per_s": 0.3, "traffic": {"headway": 1.2}}`).
    pub overrides: Option<String>,
}

impl Settings {
    /// The scenario and the environment settings.
    pub fn build(&self) -> Result<(Arc<Scenario>, EnvConfig), SimError> {
        let mut scenario = Scenario::load(&self.scenario)?;
        if let Some(json) = &self.overrides {
            scenario = with_overrides(&scenario, json)?;
        }
        if let Some(drivers) = &self.drivers {
            scenario = scenario.with_drivers(DriverPopulation::load(drivers)?)?;
        }
        let mut config = EnvConfig::for_actions(self.actions);
        if let Some(kind) = self.observation {
            config.observation = kind;
        }
        config.gamma = self.gamma;
        config.collision_reward = self.collision_reward;
        Ok((Arc::new(scenario), config))
    }
}

/// `scenario` with the JSON object `json` merged into its spec.
fn with_overrides(scenario: &Scenario, json: &str) -> Result<Scenario, SimError> {
    let invalid = |problem: String| SimError::Invalid {
        what: format!("{} overrides", scenario.name()),
        problem,
    };
    let overrides: serde_json::Value =
        serde_json::from_str(json).map_err(|e| invalid(e.to_string()))?;
    if !overrides.is_object() {
        return Err(invalid("overrides must be a table".to_owned()));
    }
    let mut spec = serde_json::to_value(scenario.spec()).map_err(|e| invalid(e.to_string()))?;
    merge(&mut spec, overrides);
    let spec: ScenarioSpec = serde_json::from_value(spec).map_err(|e| invalid(e.to_string()))?;
    Scenario::compile(spec)
}

/// Merges `top` into `base`: tables key by key, anything else replaced.
fn merge(base: &mut serde_json::Value, top: serde_json::Value) {
    match (base, top) {
        (serde_json::Value::Object(b), serde_json::Value::Object(t)) => {
            for (key, value) in t {
                match b.get_mut(&key) {
                    Some(slot) => merge(slot, value),
                    None => {
                        b.insert(key, value);
                    }
                }
            }
        }
        (slot, value) => *slot = value,
    }
}

/// Bounds of every value of a flat observation. Every value the
/// simulator writes lies inside them; [`Episode::observe`] clamps anyway,
/// so a scenario file with odd speeds cannot step outside the space.
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Least values.
    pub low: Vec<f32>,
    /// Greatest values.
    pub high: Vec<f32>,
}

impl Bounds {
    /// The bounds of `spec`'s layout in `scenario`: flags and the TTC
    /// channel in [0, 1], headings in [-1, 1], offsets in [-0.5, 0.5],
    /// speeds from 0 to the fastest a car or the ego can go (at least twice
    /// the speed limit), progress and time in [0, 1].
    pub fn of(scenario: &Scenario, spec: &ObsSpec) -> Self {
        let limit = scenario.spec().speed_limit;
        let fastest_lane = scenario
            .lanes()
            .iter()
            .map(|l| l.speed_limit)
            .fold(limit, f64::max);
        let factor = scenario
            .spec()
            .drivers
            .speed_factor_max
            .unwrap_or(0.0)
            .max(scenario.spec().traffic.speed_factor_max);
        let path = scenario.ego_path().length();
        let ego_fastest = (0..=path.ceil() as usize)
            .map(|s| scenario.ego_speed_cap(s as f64))
            .fold(0.0, f64::max);
        let speed = (fastest_lane * factor).max(ego_fastest) / limit;
        let speed = speed.max(2.0) as f32;

        let cells = spec.rows * spec.cols;
        let mut channels: Vec<(f32, f32)> = vec![(0.0, 1.0), (-1.0, 1.0), (0.0, speed)];
        if spec.kind == ObsKind::Sequential {
            channels.push((0.0, 1.0));
        }
        if spec.occlusion {
            channels.push((0.0, 1.0));
        }
        channels.extend([(-0.5, 0.5), (-0.5, 0.5)]);
        debug_assert_eq!(channels.len(), spec.channels);
        let mut low = Vec::with_capacity(spec.len());
        let mut high = Vec::with_capacity(spec.len());
        for (lo, hi) in channels {
            low.extend(std::iter::repeat_n(lo, cells));
            high.extend(std::iter::repeat_n(hi, cells));
        }
        // Ego speed, progress, committed, time used.
        low.extend([0.0; 4]);
        high.extend([speed, 1.0, 1.0, 1.0]);
        Self { low, high }
    }
}

/// One environment and where it is in its seeded sequence of episodes.
#[derive(Debug, Clone)]
pub struct Episode {
    env: Env,
    bounds: Arc<Bounds>,
    /// Base seed of the sequence.
    base: u64,
    /// Index of the running episode in the sequence.
    trial: u64,
    /// Non-zero values of the observation, reused.
    sparse: Vec<(u32, f32)>,
}

impl Episode {
    /// An environment of `scenario`, reset as trial 0 of base seed 0.
    pub fn new(scenario: &Arc<Scenario>, config: EnvConfig, bounds: Arc<Bounds>) -> Self {
        let mut env = Env::new(Arc::clone(scenario), config);
        env.reset(episode_seed(0, 0));
        Self {
            env,
            bounds,
            base: 0,
            trial: 0,
            sparse: Vec::new(),
        }
    }

    /// Starts trial 0 of base seed `base`, or with `None` the next trial of
    /// the current base.
    pub fn reset(&mut self, base: Option<u64>) {
        match base {
            Some(b) => (self.base, self.trial) = (b, 0),
            None => self.trial += 1,
        }
        self.env.reset(self.episode_seed());
    }

    /// One decision: [`Env::step`].
    pub fn step(&mut self, action: usize) -> Result<StepResult, SimError> {
        self.env.step(action)
    }

    /// Writes the observation into `row`, which holds zeros and is
    /// [`ObsSpec::len`] long, each value clamped into its bounds.
    pub fn observe(&mut self, row: &mut [f32]) {
        self.env.write_observation_sparse(&mut self.sparse);
        let Bounds { low, high } = &*self.bounds;
        for &(i, v) in &self.sparse {
            let i = i as usize;
            if let Some(slot) = row.get_mut(i) {
                *slot = v.clamp(low[i], high[i]);
            }
        }
    }

    /// The environment.
    pub fn env(&self) -> &Env {
        &self.env
    }

    /// Base seed of the running sequence.
    pub fn base(&self) -> u64 {
        self.base
    }

    /// Index of the running episode: the trial of `crossroads eval`.
    pub fn trial(&self) -> u64 {
        self.trial
    }

    /// The seed the running episode was reset with.
    pub fn episode_seed(&self) -> u64 {
        episode_seed(self.base, self.trial)
    }
}

/// Whether an outcome ends the episode as `terminated` (success,
/// collision) or as `truncated` (timeout).
pub fn ends(outcome: Option<Outcome>) -> (bool, bool) {
    match outcome {
        Some(Outcome::Success | Outcome::Collision) => (true, false),
        Some(Outcome::Timeout) => (false, true),
        None => (false, false),
    }
}

/// An outcome as a small code for arrays: 0 running, 1 success, 2
/// collision, 3 timeout.
pub fn outcome_code(outcome: Option<Outcome>) -> i8 {
    match outcome {
        None => 0,
        Some(Outcome::Success) => 1,
        Some(Outcome::Collision) => 2,
        Some(Outcome::Timeout) => 3,
    }
}

/// An outcome's name, as the CLI's JSON writes it.
pub fn outcome_name(outcome: Outcome) -> &'static str {
    match outcome {
        Outcome::Success => "success",
        Outcome::Collision => "collision",
        Outcome::Timeout => "timeout",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crossroads_sim::{EvalConfig, TtcPolicy, run_trials};

    fn settings(scenario: &str, actions: ActionSet) -> Settings {
        Settings {
            scenario: scenario.to_owned(),
            actions,
            drivers: None,
            observation: None,
            gamma: 0.99,
            collision_reward: None,
            overrides: None,
        }
    }

    #[test]
    fn episodes_are_the_trials_of_eval() {
        let (scenario, config) = settings("left", ActionSet::Ttg).build().unwrap();
        let spec = Env::new(Arc::clone(&scenario), config).obs_spec();
        let bounds = Arc::new(Bounds::of(&scenario, &spec));
        let policy = TtcPolicy::new(1.5, false);
        let eval = EvalConfig::new(ActionSet::Ttg, 40, 7);
        let trials = run_trials(&scenario, &policy, &eval, &|_| {}).unwrap();
        let mut ep = Episode::new(&scenario, config, bounds);
        ep.reset(Some(7));
        let mut row = vec![0.0; spec.len()];
        for (i, trial) in trials.iter().enumerate() {
            if i > 0 {
                ep.reset(None);
            }
            assert_eq!(ep.trial(), i as u64);
            loop {
                row.fill(0.0);
                ep.observe(&mut row);
                let Bounds { low, high } = &*ep.bounds;
                assert!(
                    row.iter()
                        .zip(low)
                        .zip(high)
                        .all(|((v, l), h)| l <= v && v <= h)
                );
                let a = ActionSet::Ttg
                    .encode(policy.intent(ep.env()), ep.env().ego().v, 1.0)
                    .unwrap();
                if ep.step(a).unwrap().done {
                    break;
                }
            }
            assert_eq!(ep.env().outcome(), Some(trial.outcome), "trial {i}");
        }
    }

    #[test]
    fn overrides_merge_into_tables() {
        let mut s = settings("left", ActionSet::Creep);
        s.overrides = Some(r#"{"step_limit": 40, "traffic": {"headway": 1.5}}"#.to_owned());
        let (scenario, config) = s.build().unwrap();
        assert_eq!(scenario.spec().step_limit, 40);
        assert_eq!(scenario.spec().traffic.headway, 1.5);
        assert_eq!(config.observation, ObsKind::Ttg);
        s.overrides = Some(r#"{"no_such_key": 1}"#.to_owned());
        assert!(s.build().is_err());
        s.overrides = Some("[1]".to_owned());
        assert!(s.build().is_err());
    }

    #[test]
    fn bounds_have_one_pair_per_value() {
        for (name, actions) in [
            ("left", ActionSet::Ttg),
            ("occluded", ActionSet::Sequential),
        ] {
            let (scenario, config) = settings(name, actions).build().unwrap();
            let spec = Env::new(Arc::clone(&scenario), config).obs_spec();
            let b = Bounds::of(&scenario, &spec);
            assert_eq!((b.low.len(), b.high.len()), (spec.len(), spec.len()));
            assert!(b.low.iter().zip(&b.high).all(|(l, h)| l < h));
        }
    }
}
