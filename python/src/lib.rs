//! The Python face of the simulator, `crossroads._native`: a thin pyo3
//! layer over `crossroads_sim` and `crossroads_draw`, beside the Python
//! package `crossroads` (python/crossroads/) that registers it with
//! Gymnasium. Never links libtorch.
//!
//! [`env::PyEnv`] is one environment whose episodes are the trials of
//! `crossroads eval` ([`episode::Episode`] holds the seeding both share);
//! [`vec_env::PyVecEnv`] steps N of them in one call with Python's lock
//! released; [`baselines`] holds the TTC rule and the shield as callables
//! on an environment's state. Renders are `crossroads render`'s pictures
//! as RGB arrays. Guide: docs/python.md.

mod baselines;
mod env;
mod episode;
mod vec_env;

use std::sync::Arc;

use crossroads_sim::{ActionSet, EnvConfig, ObsKind, Scenario};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::episode::{Bounds, Settings};

/// A Rust error as Python's `ValueError`, with its message.
pub(crate) fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// An action set by name: ttg, sequential or creep.
pub(crate) fn parse_actions(name: &str) -> PyResult<ActionSet> {
    name.parse().map_err(value_error)
}

/// A grid by name: ttg or sequential.
pub(crate) fn parse_observation(name: &str) -> PyResult<ObsKind> {
    env::observation_kind(name).ok_or_else(|| {
        value_error(format!(
            "observation {name:?}: expected ttg or sequential (the grid)"
        ))
    })
}

/// The scenario, its environment settings and the observation's bounds
/// that the keyword arguments `Env` and `VecEnv` share describe.
pub(crate) fn environment(
    scenario: &str,
    actions: &str,
    drivers: Option<String>,
    observation: Option<&str>,
    gamma: f64,
    collision_reward: Option<f64>,
    overrides: Option<String>,
) -> PyResult<(Arc<Scenario>, EnvConfig, Arc<Bounds>)> {
    let settings = Settings {
        scenario: scenario.to_owned(),
        actions: parse_actions(actions)?,
        drivers,
        observation: observation.map(parse_observation).transpose()?,
        gamma,
        collision_reward,
        overrides,
    };
    let (scenario, config) = settings.build().map_err(value_error)?;
    let spec = config.observation.spec(scenario.occlusion_channels());
    let bounds = Arc::new(Bounds::of(&scenario, &spec));
    Ok((scenario, config, bounds))
}

/// Names of the built-in scenarios (the occlusion family also takes
/// `occluded-<30|60|90>[-<left|right|both>]`).
#[pyfunction]
fn builtin_scenarios() -> Vec<&'static str> {
    Scenario::builtin_names()
}

/// Seed of trial `trial` of `crossroads eval --seed base`.
#[pyfunction]
fn episode_seed(base: u64, trial: u64) -> u64 {
    crossroads_sim::episode_seed(base, trial)
}

/// Random TTG decisions per second of the simulator alone on one thread,
/// each followed by writing the observation (`crossroads bench sim`'s
/// figure), measured for about `2 * seconds`: the reference for the
/// Python face's throughput on the same machine.
#[pyfunction]
#[pyo3(signature = (scenario="right", seconds=1.0))]
fn bench_simulator(py: Python<'_>, scenario: &str, seconds: f64) -> PyResult<f64> {
    let scenario = Arc::new(Scenario::load(scenario).map_err(value_error)?);
    let min = std::time::Duration::from_secs_f64(seconds.max(0.01));
    py.detach(|| crossroads_sim::bench_scenario(&scenario, min))
        .map(|f| f.decisions_per_s)
        .map_err(value_error)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<env::PyEnv>()?;
    m.add_class::<vec_env::PyVecEnv>()?;
    m.add_class::<baselines::PyTtc>()?;
    m.add_class::<baselines::PyShield>()?;
    m.add_function(wrap_pyfunction!(builtin_scenarios, m)?)?;
    m.add_function(wrap_pyfunction!(episode_seed, m)?)?;
    m.add_function(wrap_pyfunction!(bench_simulator, m)?)?;
    m.add("DRIVER_PRESETS", crossroads_sim::DRIVER_PRESETS.to_vec())?;
    Ok(())
}
