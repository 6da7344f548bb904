//! Throughput measurement of the simulator, for `crossroads bench sim` and
//! the criterion benches.

use std::sync::Arc;
use std::time::{Duration, Instant};

use rand::{RngExt, SeedableRng};
use serde::Serialize;

use crate::action::ActionSet;
use crate::env::{Env, EnvConfig};
use crate::error::SimError;
use crate::policy::PolicyRng;
use crate::scenario::Scenario;

/// Throughput of one scenario on one thread.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BenchFigures {
    /// Scenario name.
    pub scenario: String,
    /// Random TTG decisions per second, each followed by writing the TTG
    /// observation; resets (with their traffic warm-up) included.
    pub decisions_per_s: f64,
    /// Simulation steps per second (traffic, ego, collision check) of an
    /// ego that waits; resets included.
    pub steps_per_s: f64,
    /// Mean number of traffic cars during the step measurement.
    pub mean_cars: f64,
}

/// Runs `f` in a loop for at least `min` and returns (iterations, seconds).
fn timed(min: Duration, mut f: impl FnMut() -> u64) -> (u64, f64) {
    let start = Instant::now();
    let mut n = 0;
    while start.elapsed() < min {
        n += f();
    }
    (n, start.elapsed().as_secs_f64())
}

/// Measures one scenario on the calling thread for about `2 * min`.
pub fn bench_scenario(scenario: &Arc<Scenario>, min: Duration) -> Result<BenchFigures, SimError> {
    let mut env = Env::new(Arc::clone(scenario), EnvConfig::for_actions(ActionSet::Ttg));
    let mut obs = vec![0.0f32; env.obs_spec().len()];
    let mut rng = PolicyRng::seed_from_u64(1);
    let mut episode = 0u64;
    let mut err = None;
    let (decisions, secs) = timed(min, || {
        let mut n = 0;
        for _ in 0..256 {
            let a = rng.random_range(0..5);
            match env.step(a) {
                Ok(r) if r.done => {
                    episode += 1;
                    env.reset(episode);
                }
                Ok(_) => {}
                Err(e) => err = Some(e),
            }
            if let Err(e) = env.write_observation(&mut obs) {
                err = Some(e);
            }
            n += 1;
        }
        n
    });
    if let Some(e) = err {
        return Err(e);
    }
    let decisions_per_s = decisions as f64 / secs;
    let mut cars = 0u64;
    let (steps, secs) = timed(min, || {
        let mut n = 0;
        for _ in 0..256 {
            // Action 1 of TTG: wait one step.
            match env.step(1) {
                Ok(r) if r.done => {
                    episode += 1;
                    env.reset(episode);
                }
                Ok(_) => {}
                Err(e) => err = Some(e),
            }
            cars += env.traffic().len() as u64;
            n += 1;
        }
        n
    });
    if let Some(e) = err {
        return Err(e);
    }
    Ok(BenchFigures {
        scenario: scenario.name().to_owned(),
        decisions_per_s,
        steps_per_s: steps as f64 / secs,
        mean_cars: cars as f64 / steps.max(1) as f64,
    })
}

/// [`bench_scenario`] for every built-in scenario (the occlusion family as
/// `occluded`).
pub fn bench_builtin(min: Duration) -> Result<Vec<BenchFigures>, SimError> {
    Scenario::builtin_names()
        .into_iter()
        .map(|name| bench_scenario(&Arc::new(Scenario::builtin(name)?), min))
        .collect()
}
