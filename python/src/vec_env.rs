//! `crossroads._native.VecEnv`: N environments stepped in Rust in one call,
//! with Python's lock released, in Gymnasium's two autoreset modes; what
//! `crossroads.CrossroadsVectorEnv` wraps.
//!
//! Environment `i` after `reset([s0, s1, ...])` is a single environment
//! after `reset(seed=s_i)`, step for step: its episodes are the trials of
//! `crossroads eval --seed s_i`. Every array a step returns is filled as
//! Gymnasium's `SyncVectorEnv` fills its infos from single environments
//! (0 where an environment has no such value).

use std::sync::Arc;

use crossroads_sim::SimError;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use rayon::prelude::*;

use crate::episode::{Episode, ends, outcome_code};
use crate::{environment, value_error};

/// When a finished environment starts its next episode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Autoreset {
    /// On the step after the one that ended it, whose action is ignored
    /// (Gymnasium 1.x's default).
    NextStep,
    /// At once: the step returns the next episode's first observation and
    /// the last one in `final_obs`.
    SameStep,
}

/// What one environment did in one step.
#[derive(Debug, Clone, Copy, Default)]
struct Row {
    reward: f64,
    terminated: bool,
    truncated: bool,
    /// It stepped (rather than being reset, in next-step mode).
    stepped: bool,
    steps: u32,
    discount: f64,
    outcome: i8,
    /// Its episode ended and it was reset in this step (same-step mode).
    ended: bool,
    /// Trial and seed of the episode that ended, when `ended`.
    final_trial: u64,
    final_seed: u64,
}

/// One environment and whether it waits for its reset.
#[derive(Debug)]
struct Slot {
    episode: Episode,
    pending_reset: bool,
}

impl Slot {
    fn step(
        &mut self,
        action: i64,
        mode: Autoreset,
        gamma: f64,
        obs: &mut [f32],
        final_obs: Option<&mut [f32]>,
    ) -> Result<Row, SimError> {
        let mut row = Row::default();
        if self.pending_reset {
            self.pending_reset = false;
            self.episode.reset(None);
            self.episode.observe(obs);
            return Ok(row);
        }
        let action = usize::try_from(action).map_err(|_| SimError::ActionOutOfRange {
            action: usize::MAX,
            set: self.episode.env().config().action_set.name(),
            count: self.episode.env().config().action_set.num_actions(),
        })?;
        let r = self.episode.step(action)?;
        (row.terminated, row.truncated) = ends(r.outcome);
        row.reward = r.reward;
        row.stepped = true;
        row.steps = r.steps;
        row.discount = gamma.powi(r.steps as i32);
        row.outcome = outcome_code(r.outcome);
        if r.done {
            match (mode, final_obs) {
                (Autoreset::SameStep, Some(last)) => {
                    last.fill(0.0);
                    self.episode.observe(last);
                    row.ended = true;
                    row.final_trial = self.episode.trial();
                    row.final_seed = self.episode.episode_seed();
                    self.episode.reset(None);
                }
                _ => self.pending_reset = true,
            }
        }
        self.episode.observe(obs);
        Ok(row)
    }
}

/// One environment's share of a step: where its results go.
#[derive(Debug)]
struct Job<'a> {
    slot: &'a mut Slot,
    obs: &'a mut [f32],
    last: Option<&'a mut [f32]>,
    row: &'a mut Row,
    action: i64,
}

impl Job<'_> {
    fn run(&mut self, mode: Autoreset, gamma: f64) -> Result<(), SimError> {
        *self.row = self
            .slot
            .step(self.action, mode, gamma, self.obs, self.last.as_deref_mut())?;
        Ok(())
    }
}

/// N environments of one scenario and action set.
#[pyclass(module = "crossroads._native", name = "VecEnv")]
#[derive(Debug)]
pub struct PyVecEnv {
    slots: Vec<Slot>,
    obs_len: usize,
    gamma: f64,
    mode: Autoreset,
    /// Last observations of the episodes that end in a step (same-step
    /// mode), a row per environment.
    last: Vec<f32>,
    /// A pool of its own for more than one thread; `None` steps on the
    /// calling thread.
    pool: Option<rayon::ThreadPool>,
}

impl PyVecEnv {
    /// Number of environments.
    pub(crate) fn len(&self) -> usize {
        self.slots.len()
    }

    /// Environment `i`, for the baselines.
    pub(crate) fn episode(&self, i: usize) -> Option<&Episode> {
        self.slots.get(i).map(|s| &s.episode)
    }

    fn seed_arrays<'py>(
        &self,
        py: Python<'py>,
    ) -> (Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>) {
        let base: Vec<u64> = self.slots.iter().map(|s| s.episode.base()).collect();
        let trial: Vec<u64> = self.slots.iter().map(|s| s.episode.trial()).collect();
        let seed: Vec<u64> = self
            .slots
            .iter()
            .map(|s| s.episode.episode_seed())
            .collect();
        (
            base.into_pyarray(py).into_any(),
            trial.into_pyarray(py).into_any(),
            seed.into_pyarray(py).into_any(),
        )
    }

    /// `flat`, rows of one observation each, as a numpy array.
    fn rows_to_array<'py>(
        &self,
        py: Python<'py>,
        flat: Vec<f32>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        Ok(
            Array2::from_shape_vec((flat.len() / self.obs_len, self.obs_len), flat)
                .map_err(value_error)?
                .into_pyarray(py),
        )
    }
}

#[pymethods]
impl PyVecEnv {
    #[new]
    // Python's keyword arguments.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (num_envs, scenario="left", actions="ttg", drivers=None, observation=None, gamma=0.99, collision_reward=None, overrides=None, autoreset="next-step", threads=1))]
    fn new(
        num_envs: usize,
        scenario: &str,
        actions: &str,
        drivers: Option<String>,
        observation: Option<&str>,
        gamma: f64,
        collision_reward: Option<f64>,
        overrides: Option<String>,
        autoreset: &str,
        threads: usize,
    ) -> PyResult<Self> {
        if num_envs == 0 {
            return Err(value_error("num_envs must be at least 1"));
        }
        let mode = match autoreset {
            "next-step" => Autoreset::NextStep,
            "same-step" => Autoreset::SameStep,
            other => {
                return Err(value_error(format!(
                    "autoreset {other:?}: expected next-step or same-step"
                )));
            }
        };
        let (scenario, config, bounds) = environment(
            scenario,
            actions,
            drivers,
            observation,
            gamma,
            collision_reward,
            overrides,
        )?;
        let pool = match threads {
            1 => None,
            n => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(value_error)?,
            ),
        };
        Ok(Self {
            slots: (0..num_envs)
                .map(|_| Slot {
                    episode: Episode::new(&scenario, config, Arc::clone(&bounds)),
                    pending_reset: false,
                })
                .collect(),
            obs_len: bounds.low.len(),
            gamma,
            mode,
            last: Vec::new(),
            pool,
        })
    }

    /// Number of environments.
    #[getter]
    fn num_envs(&self) -> usize {
        self.slots.len()
    }

    /// Resets every environment: `seeds[i]` a base seed, or `None` for its
    /// next trial. Returns the observations (`N x obs_len`) and each one's
    /// base seed, trial and episode seed.
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seeds: Vec<Option<u64>>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        if seeds.len() != self.slots.len() {
            return Err(value_error(format!(
                "{} seeds for {} environments",
                seeds.len(),
                self.slots.len()
            )));
        }
        let mut obs = vec![0.0f32; self.slots.len() * self.obs_len];
        for ((slot, seed), row) in self
            .slots
            .iter_mut()
            .zip(seeds)
            .zip(obs.chunks_exact_mut(self.obs_len))
        {
            slot.pending_reset = false;
            slot.episode.reset(seed);
            slot.episode.observe(row);
        }
        let obs = self.rows_to_array(py, obs)?;
        let (base, trial, seed) = self.seed_arrays(py);
        PyTuple::new(py, [obs.into_any(), base, trial, seed])
    }

    /// Applies `actions[i]` to environment `i`. Returns `(obs, rewards,
    /// terminated, truncated, stepped, steps, discount, outcome, base,
    /// trial, episode_seed, final)`: `stepped` is false where the
    /// environment was reset instead (next-step mode); `outcome` codes 0
    /// running, 1 success, 2 collision, 3 timeout; the seed arrays are of
    /// the episode now running; `final` is `None`, or in same-step mode
    /// where an episode ended `(ended, final_obs, final_trial,
    /// final_episode_seed)`, `final_obs` a row for each ended environment
    /// in order.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: PyReadonlyArray1<'py, i64>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let actions = actions.as_slice().map_err(value_error)?;
        let n = self.slots.len();
        if actions.len() != n {
            return Err(value_error(format!(
                "{} actions for {n} environments",
                actions.len()
            )));
        }
        let (len, mode, gamma) = (self.obs_len, self.mode, self.gamma);
        let same_step = mode == Autoreset::SameStep;
        // numpy's own zeroed arrays: cheaper to get each step than large
        // fresh Rust vectors.
        let obs_array = PyArray2::<f32>::zeros(py, [n, len], false);
        let mut obs_view = obs_array.readwrite();
        let obs = obs_view.as_slice_mut().map_err(value_error)?;
        // Last observations go to rows of a buffer kept across steps; the
        // ended environments' rows are copied out below.
        self.last.resize(if same_step { n * len } else { 0 }, 0.0);
        let last = &mut self.last;
        let mut rows = vec![Row::default(); n];
        let slots = &mut self.slots;
        let pool = self.pool.as_ref();
        let outcome: Result<(), SimError> = py.detach(|| {
            let mut lasts: Vec<Option<&mut [f32]>> = if same_step {
                last.chunks_exact_mut(len).map(Some).collect()
            } else {
                (0..n).map(|_| None).collect()
            };
            let mut jobs: Vec<Job<'_>> = slots
                .iter_mut()
                .zip(obs.chunks_exact_mut(len))
                .zip(lasts.iter_mut())
                .zip(rows.iter_mut())
                .zip(actions)
                .map(|((((slot, obs), last), row), &action)| Job {
                    slot,
                    obs,
                    last: last.take(),
                    row,
                    action,
                })
                .collect();
            match pool {
                None => jobs.iter_mut().try_for_each(|j| j.run(mode, gamma)),
                Some(pool) => {
                    pool.install(|| jobs.par_iter_mut().try_for_each(|j| j.run(mode, gamma)))
                }
            }
        });
        outcome.map_err(value_error)?;
        drop(obs_view);

        let obs = obs_array.into_any();
        let col = |f: &dyn Fn(&Row) -> f64| -> Vec<f64> { rows.iter().map(f).collect() };
        let flag = |f: &dyn Fn(&Row) -> bool| -> Vec<bool> { rows.iter().map(f).collect() };
        let rewards = col(&|r| r.reward).into_pyarray(py).into_any();
        let terminated = flag(&|r| r.terminated).into_pyarray(py).into_any();
        let truncated = flag(&|r| r.truncated).into_pyarray(py).into_any();
        let stepped = flag(&|r| r.stepped).into_pyarray(py).into_any();
        let steps: Vec<i64> = rows.iter().map(|r| i64::from(r.steps)).collect();
        let steps = steps.into_pyarray(py).into_any();
        let discount = col(&|r| r.discount).into_pyarray(py).into_any();
        let outcome: Vec<i8> = rows.iter().map(|r| r.outcome).collect();
        let outcome = outcome.into_pyarray(py).into_any();
        let (base, trial, seed) = self.seed_arrays(py);
        let final_part = if rows.iter().any(|r| r.ended) {
            let ended = flag(&|r| r.ended).into_pyarray(py).into_any();
            let mut rows_out = Vec::new();
            for (row, r) in self.last.chunks_exact(len).zip(&rows) {
                if r.ended {
                    rows_out.extend_from_slice(row);
                }
            }
            let last = self.rows_to_array(py, rows_out)?.into_any();
            let ft: Vec<u64> = rows.iter().map(|r| r.final_trial).collect();
            let fs: Vec<u64> = rows.iter().map(|r| r.final_seed).collect();
            PyTuple::new(
                py,
                [
                    ended,
                    last,
                    ft.into_pyarray(py).into_any(),
                    fs.into_pyarray(py).into_any(),
                ],
            )?
            .into_any()
        } else {
            py.None().into_bound(py)
        };
        PyTuple::new(
            py,
            [
                obs, rewards, terminated, truncated, stepped, steps, discount, outcome, base,
                trial, seed, final_part,
            ],
        )
    }

    /// Environment `i`'s state drawn as `Env.render` draws it.
    #[pyo3(signature = (i, grid=false, scale=None))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        i: usize,
        grid: bool,
        scale: Option<f64>,
    ) -> PyResult<Bound<'py, numpy::PyArray3<u8>>> {
        let slot = self
            .slots
            .get(i)
            .ok_or_else(|| value_error(format!("no environment {i}")))?;
        crate::env::render(py, slot.episode.env(), grid, scale)
    }

    /// The outcome of environment `i`'s episode so far, by name.
    fn outcome(&self, i: usize) -> Option<&'static str> {
        self.slots
            .get(i)
            .and_then(|s| s.episode.env().outcome())
            .map(crate::episode::outcome_name)
    }
}
