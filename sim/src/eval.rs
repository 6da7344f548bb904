//! Evaluation of a policy over many seeded trials, in parallel, with the
//! same result whatever the number of threads.
//!
//! Each trial's seed derives from the base seed and its index (the `seed`
//! module), trials run on the rayon pool, and the summary's intervals are
//! 95 %: Wilson score intervals for rates, normal intervals for means.

use std::sync::Arc;

use rand::SeedableRng;
use rayon::prelude::*;
use serde::Serialize;

use crate::action::ActionSet;
use crate::env::{Env, EnvConfig, Outcome};
use crate::error::SimError;
use crate::policy::{Policy, PolicyRng};
use crate::scenario::Scenario;
use crate::seed::{episode_seed, policy_seed};

/// z of a two-sided 95 % interval.
const Z95: f64 = 1.959_963_984_540_054;

/// Settings of [`evaluate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalConfig {
    /// Action set the policy drives.
    pub action_set: ActionSet,
    /// Number of trials.
    pub trials: u64,
    /// Base seed; trial `i` uses [`crate::episode_seed`]`(seed, i)`.
    pub seed: u64,
    /// Environments a policy decides for in one call.
    pub batch: usize,
}

impl EvalConfig {
    /// `trials` trials from `seed`, batches of 32.
    pub fn new(action_set: ActionSet, trials: u64, seed: u64) -> Self {
        Self {
            action_set,
            trials,
            seed,
            batch: 32,
        }
    }
}

/// A closed interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Interval {
    /// Lower end.
    pub low: f64,
    /// Upper end.
    pub high: f64,
}

/// Result of one trial.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrialResult {
    /// How it ended.
    pub outcome: Outcome,
    /// Episode length, s (time to goal on success).
    pub time_s: f64,
    /// Braking time of traffic, s.
    pub brake_s: f64,
    /// Brake-light time of traffic by SUMO's rule, s
    /// ([`crate::Traffic::brake_light_time_s`]).
    pub brake_light_s: f64,
    /// Seconds before the ego chose *go*; `None` if it never did.
    pub wait_s: Option<f64>,
    /// The ego's front past the creep limit (m, negative short of it) and
    /// its speed (m/s) when it chose *go*; `None` if it never did (or the
    /// trial was not simulated here).
    pub go_state: Option<(f64, f64)>,
    /// Undiscounted return under the scenario's rewards
    /// ([`crate::Rewards::episode_return`]).
    pub episode_return: f64,
}

/// What [`evaluate`] measured. Rates are fractions in `[0, 1]`; intervals
/// are 95 %: Wilson score intervals for rates, normal intervals for means.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    /// Scenario name.
    pub scenario: String,
    /// Policy name.
    pub policy: String,
    /// Action set name.
    pub action_set: String,
    /// Trials run.
    pub trials: u64,
    /// Base seed.
    pub seed: u64,
    /// Fraction of trials that reached the goal.
    pub success_rate: f64,
    /// Its interval.
    pub success_ci: Interval,
    /// Fraction that collided.
    pub collision_rate: f64,
    /// Its interval.
    pub collision_ci: Interval,
    /// Fraction that timed out.
    pub timeout_rate: f64,
    /// Its interval.
    pub timeout_ci: Interval,
    /// Mean time to goal of the successful trials, s; `None` without any.
    pub mean_time_s: Option<f64>,
    /// Its interval.
    pub mean_time_ci: Option<Interval>,
    /// Mean braking time of traffic per trial (all trials), s.
    pub mean_brake_s: f64,
    /// Its interval.
    pub mean_brake_ci: Interval,
    /// Mean brake-light time of traffic per trial by SUMO's rule (all
    /// trials), s.
    pub mean_brake_light_s: f64,
    /// Its interval.
    pub mean_brake_light_ci: Interval,
    /// Mean wait before *go* over the trials that went, s; `None` if none
    /// did.
    pub mean_wait_s: Option<f64>,
    /// Its interval.
    pub mean_wait_ci: Option<Interval>,
    /// Mean of the ego's front past the creep limit when it chose *go*
    /// (negative: short of it), m, over the trials that went; `None` if
    /// none did.
    pub mean_go_offset_m: Option<f64>,
    /// Mean ego speed when it chose *go*, m/s, over the trials that went.
    pub mean_go_speed: Option<f64>,
    /// Mean undiscounted return per trial under the scenario's rewards
    /// (+1 success, -10 collision, -0.01 a step by default): the task's
    /// objective, by which training keeps its best weights.
    pub mean_return: f64,
    /// Its interval.
    pub mean_return_ci: Interval,
}

/// Runs `config.trials` trials of `policy` on `scenario` on the rayon pool
/// and summarizes them. `progress` is called with the number of trials
/// just finished (from worker threads). The report is the same for the same
/// seed whatever the number of threads.
pub fn evaluate(
    scenario: &Arc<Scenario>,
    policy: &dyn Policy,
    config: &EvalConfig,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<EvalReport, SimError> {
    let results = run_trials(scenario, policy, config, progress)?;
    Ok(summarize(scenario.name(), &policy.name(), config, &results))
}

/// Runs the trials and returns their results in trial order.
pub fn run_trials(
    scenario: &Arc<Scenario>,
    policy: &dyn Policy,
    config: &EvalConfig,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<Vec<TrialResult>, SimError> {
    run_trials_watched(scenario, policy, config, progress, &|_, _, _| Ok(()))
}

/// What [`run_trials_watched`] calls before each action is applied: the
/// trial, its environment and the action chosen in it.
pub(crate) type Watch<'a> = dyn Fn(u64, &Env, usize) -> Result<(), SimError> + Sync + 'a;

/// [`run_trials`], calling `watch` with every decision before it is
/// applied (from worker threads, in no fixed order across trials).
pub(crate) fn run_trials_watched(
    scenario: &Arc<Scenario>,
    policy: &dyn Policy,
    config: &EvalConfig,
    progress: &(dyn Fn(u64) + Sync),
    watch: &Watch<'_>,
) -> Result<Vec<TrialResult>, SimError> {
    if config.batch == 0 {
        return Err(SimError::EvalConfig("batch must be at least 1".to_owned()));
    }
    policy.supports(config.action_set)?;
    // Chunks fixed by the trial count alone, so threads only change who
    // runs a chunk, never what it computes.
    let chunk = (config.batch as u64 * 4).max(1);
    let chunks = config.trials.div_ceil(chunk);
    let per_chunk: Vec<Vec<TrialResult>> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let start = c * chunk;
            let end = (start + chunk).min(config.trials);
            run_chunk(scenario, policy, config, (start, end), progress, watch)
        })
        .collect::<Result<_, _>>()?;
    Ok(per_chunk.into_iter().flatten().collect())
}

fn run_chunk(
    scenario: &Arc<Scenario>,
    policy: &dyn Policy,
    config: &EvalConfig,
    (start, end): (u64, u64),
    progress: &(dyn Fn(u64) + Sync),
    watch: &Watch<'_>,
) -> Result<Vec<TrialResult>, SimError> {
    let n = (end - start) as usize;
    let slots = config.batch.min(n);
    let mut results: Vec<Option<TrialResult>> = vec![None; n];
    let env_config = EnvConfig::for_actions(config.action_set);
    let mut envs = Vec::with_capacity(slots);
    let mut rngs = Vec::with_capacity(slots);
    let mut ids = Vec::with_capacity(slots);
    let mut actions = vec![0usize; slots];
    let mut next = start;
    while envs.len() < slots {
        let mut env = Env::new(Arc::clone(scenario), env_config);
        env.reset(episode_seed(config.seed, next));
        envs.push(env);
        rngs.push(PolicyRng::seed_from_u64(policy_seed(config.seed, next)));
        ids.push(next);
        next += 1;
    }
    while !envs.is_empty() {
        let live = envs.len();
        policy.act(&envs, &mut rngs, &mut actions[..live])?;
        for ((env, &a), &id) in envs.iter_mut().zip(&actions).zip(&ids) {
            watch(id, env, a)?;
            env.step(a)?;
        }
        let mut i = 0;
        while i < envs.len() {
            if !envs[i].is_done() {
                i += 1;
                continue;
            }
            let m = envs[i].metrics();
            if let Some(outcome) = m.outcome {
                results[(ids[i] - start) as usize] = Some(TrialResult {
                    outcome,
                    time_s: m.time_s,
                    brake_s: m.brake_time_s,
                    brake_light_s: m.brake_light_s,
                    wait_s: m.wait_s,
                    go_state: m.go_state,
                    episode_return: scenario.spec().rewards.episode_return(outcome, m.steps),
                });
            }
            progress(1);
            if next < end {
                envs[i].reset(episode_seed(config.seed, next));
                rngs[i] = PolicyRng::seed_from_u64(policy_seed(config.seed, next));
                ids[i] = next;
                next += 1;
                i += 1;
            } else {
                envs.swap_remove(i);
                rngs.swap_remove(i);
                ids.swap_remove(i);
            }
        }
    }
    results
        .into_iter()
        .map(|r| {
            r.ok_or_else(|| SimError::EvalConfig("a trial ended without an outcome".to_owned()))
        })
        .collect()
}

/// Summarizes trial results (in trial order) into a report.
pub fn summarize(
    scenario: &str,
    policy: &str,
    config: &EvalConfig,
    results: &[TrialResult],
) -> EvalReport {
    let n = results.len() as u64;
    let count = |o: Outcome| results.iter().filter(|r| r.outcome == o).count() as u64;
    let (succ, coll, tout) = (
        count(Outcome::Success),
        count(Outcome::Collision),
        count(Outcome::Timeout),
    );
    let times: Vec<f64> = results
        .iter()
        .filter(|r| r.outcome == Outcome::Success)
        .map(|r| r.time_s)
        .collect();
    let brakes: Vec<f64> = results.iter().map(|r| r.brake_s).collect();
    let lights: Vec<f64> = results.iter().map(|r| r.brake_light_s).collect();
    let waits: Vec<f64> = results.iter().filter_map(|r| r.wait_s).collect();
    let returns: Vec<f64> = results.iter().map(|r| r.episode_return).collect();
    let ret = mean_ci(&returns);
    let time = mean_ci(&times);
    let brake = mean_ci(&brakes);
    let light = mean_ci(&lights);
    let wait = mean_ci(&waits);
    let gone: Vec<(f64, f64)> = results.iter().filter_map(|r| r.go_state).collect();
    let go_offsets: Vec<f64> = gone.iter().map(|g| g.0).collect();
    let go_speeds: Vec<f64> = gone.iter().map(|g| g.1).collect();
    let zero = Interval {
        low: 0.0,
        high: 0.0,
    };
    EvalReport {
        scenario: scenario.to_owned(),
        policy: policy.to_owned(),
        action_set: config.action_set.name().to_owned(),
        trials: n,
        seed: config.seed,
        success_rate: rate(succ, n),
        success_ci: wilson(succ, n),
        collision_rate: rate(coll, n),
        collision_ci: wilson(coll, n),
        timeout_rate: rate(tout, n),
        timeout_ci: wilson(tout, n),
        mean_time_s: time.map(|t| t.0),
        mean_time_ci: time.map(|t| t.1),
        mean_brake_s: brake.map_or(0.0, |b| b.0),
        mean_brake_ci: brake.map_or(zero, |b| b.1),
        mean_brake_light_s: light.map_or(0.0, |b| b.0),
        mean_brake_light_ci: light.map_or(zero, |b| b.1),
        mean_wait_s: wait.map(|w| w.0),
        mean_wait_ci: wait.map(|w| w.1),
        mean_go_offset_m: mean_ci(&go_offsets).map(|m| m.0),
        mean_go_speed: mean_ci(&go_speeds).map(|m| m.0),
        mean_return: ret.map_or(0.0, |r| r.0),
        mean_return_ci: ret.map_or(zero, |r| r.1),
    }
}

fn rate(k: u64, n: u64) -> f64 {
    if n == 0 { 0.0 } else { k as f64 / n as f64 }
}

/// Wilson score interval of `k` successes in `n` trials.
pub fn wilson(k: u64, n: u64) -> Interval {
    if n == 0 {
        return Interval {
            low: 0.0,
            high: 1.0,
        };
    }
    let n = n as f64;
    let p = k as f64 / n;
    let z2 = Z95 * Z95;
    let denom = 1.0 + z2 / n;
    let center = (p + z2 / (2.0 * n)) / denom;
    let half = Z95 * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt() / denom;
    Interval {
        low: (center - half).max(0.0),
        high: (center + half).min(1.0),
    }
}

/// Mean of `xs` with its 95 % normal interval; `None` when empty.
pub fn mean_ci(xs: &[f64]) -> Option<(f64, Interval)> {
    if xs.is_empty() {
        return None;
    }
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = if xs.len() > 1 {
        xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    let half = Z95 * (var / n).sqrt();
    Some((
        mean,
        Interval {
            low: mean - half,
            high: mean + half,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_interval_values() {
        // 50 of 100: 0.5 +- 0.0962 (textbook value 0.4038 .. 0.5962).
        let i = wilson(50, 100);
        assert!(
            (i.low - 0.4038).abs() < 1e-3 && (i.high - 0.5962).abs() < 1e-3,
            "{i:?}"
        );
        // 0 of 10000 still has a positive upper end.
        let z = wilson(0, 10_000);
        assert_eq!(z.low, 0.0);
        assert!(z.high > 0.0 && z.high < 5e-4);
    }

    #[test]
    fn mean_interval() {
        let (m, i) = mean_ci(&[1.0, 2.0, 3.0]).unwrap();
        assert_eq!(m, 2.0);
        assert!((i.high - 2.0 - Z95 / 3f64.sqrt()).abs() < 1e-12);
        assert!(mean_ci(&[]).is_none());
    }
}
