//! `crossroads._native.Env`: one environment, stepped and observed from
//! Python; what `crossroads.CrossroadsEnv` wraps.

use std::sync::Arc;

use crossroads_sim::{Env, ObsKind, RenderView, Scene, SceneOptions};
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::episode::{Bounds, Episode, ends, outcome_name};
use crate::{environment, value_error};

/// One environment: `reset(seed)` starts trial 0 of `crossroads eval
/// --seed seed`, `reset(None)` the next trial; `step(action)` returns
/// Gymnasium's five values with the observation as a flat float32 array.
#[pyclass(module = "crossroads._native", name = "Env")]
#[derive(Debug)]
pub struct PyEnv {
    pub(crate) episode: Episode,
    bounds: Arc<Bounds>,
    /// numpy.uint64, for seeds above 2^63 in infos.
    uint64: Py<PyAny>,
}

impl PyEnv {
    fn observation<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        let mut row = vec![0.0f32; self.bounds.low.len()];
        self.episode.observe(&mut row);
        row.into_pyarray(py)
    }

    /// The seed keys every info has.
    fn seed_info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let info = PyDict::new(py);
        info.set_item("seed", self.episode.base())?;
        info.set_item("trial", self.episode.trial())?;
        info.set_item(
            "episode_seed",
            self.uint64.call1(py, (self.episode.episode_seed(),))?,
        )?;
        Ok(info)
    }
}

#[pymethods]
impl PyEnv {
    #[new]
    // Python's keyword arguments.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (scenario="left", actions="ttg", drivers=None, observation=None, gamma=0.99, collision_reward=None, overrides=None))]
    fn new(
        py: Python<'_>,
        scenario: &str,
        actions: &str,
        drivers: Option<String>,
        observation: Option<&str>,
        gamma: f64,
        collision_reward: Option<f64>,
        overrides: Option<String>,
    ) -> PyResult<Self> {
        let (scenario, config, bounds) = environment(
            scenario,
            actions,
            drivers,
            observation,
            gamma,
            collision_reward,
            overrides,
        )?;
        let uint64 = py.import("numpy")?.getattr("uint64")?.unbind();
        Ok(Self {
            episode: Episode::new(&scenario, config, Arc::clone(&bounds)),
            bounds,
            uint64,
        })
    }

    /// Starts trial 0 of base seed `seed`, or with `None` the next trial;
    /// returns the observation and an info of `seed`, `trial` and
    /// `episode_seed` (the seed `crossroads render` replays).
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seed: Option<u64>,
    ) -> PyResult<(Bound<'py, PyArray1<f32>>, Bound<'py, PyDict>)> {
        self.episode.reset(seed);
        Ok((self.observation(py), self.seed_info(py)?))
    }

    /// Applies one action: `(observation, reward, terminated, truncated,
    /// info)`. The reward is the discounted sum over the simulator steps
    /// the action took; info has `steps` (how many), `discount`
    /// (gamma^steps, to bootstrap with), `outcome`, `is_success` and the
    /// seed keys of `reset`.
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        action: usize,
    ) -> PyResult<(
        Bound<'py, PyArray1<f32>>,
        f64,
        bool,
        bool,
        Bound<'py, PyDict>,
    )> {
        let r = self.episode.step(action).map_err(value_error)?;
        let (terminated, truncated) = ends(r.outcome);
        let info = self.seed_info(py)?;
        info.set_item("steps", r.steps)?;
        let gamma = self.episode.env().config().gamma;
        info.set_item("discount", gamma.powi(r.steps as i32))?;
        info.set_item("outcome", r.outcome.map(outcome_name))?;
        info.set_item(
            "is_success",
            r.outcome == Some(crossroads_sim::Outcome::Success),
        )?;
        Ok((self.observation(py), r.reward, terminated, truncated, info))
    }

    /// The current observation.
    fn observe<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        self.observation(py)
    }

    /// The current state drawn as `crossroads render` draws it, as a
    /// `height x width x 3` uint8 array; `grid` overlays the observation
    /// grid, `scale` sets pixels per metre.
    #[pyo3(signature = (grid=false, scale=None))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        grid: bool,
        scale: Option<f64>,
    ) -> PyResult<Bound<'py, numpy::PyArray3<u8>>> {
        render(py, self.episode.env(), grid, scale)
    }

    /// Least values of the flat observation.
    #[getter]
    fn obs_low<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, &self.bounds.low)
    }

    /// Greatest values of the flat observation.
    #[getter]
    fn obs_high<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_slice(py, &self.bounds.high)
    }

    /// `(channels, rows, cols)` of the grid that starts the observation.
    #[getter]
    fn grid_shape(&self) -> (usize, usize, usize) {
        let s = self.episode.env().obs_spec();
        (s.channels, s.rows, s.cols)
    }

    /// Values after the grid: ego speed, progress, committed, time used.
    #[getter]
    fn ego_features(&self) -> usize {
        self.episode.env().obs_spec().ego_features
    }

    /// The observation view's name: ttg, sequential, with `-occlusion`.
    #[getter]
    fn observation_name(&self) -> String {
        self.episode.env().obs_spec().name()
    }

    /// Size of the action set.
    #[getter]
    fn num_actions(&self) -> usize {
        self.episode.env().config().action_set.num_actions()
    }

    /// The action set's name.
    #[getter]
    fn action_set(&self) -> &'static str {
        self.episode.env().config().action_set.name()
    }

    /// The index of a final *go*, where the action set has one.
    #[getter]
    fn absorbing_go(&self) -> Option<usize> {
        self.episode.env().config().action_set.absorbing_go()
    }

    /// The scenario's name.
    #[getter]
    fn scenario(&self) -> String {
        self.episode.env().scenario().name().to_owned()
    }

    /// Seconds per simulator step.
    #[getter]
    fn dt(&self) -> f64 {
        self.episode.env().scenario().dt()
    }

    /// Base seed of the running sequence of episodes.
    #[getter]
    fn seed(&self) -> u64 {
        self.episode.base()
    }

    /// Index of the running episode in it (the trial of `crossroads eval`).
    #[getter]
    fn trial(&self) -> u64 {
        self.episode.trial()
    }

    /// The seed the running episode was reset with.
    #[getter]
    fn episode_seed(&self) -> u64 {
        self.episode.episode_seed()
    }

    /// Simulator steps taken in this episode.
    #[getter]
    fn steps(&self) -> u32 {
        self.episode.env().steps()
    }

    /// How the episode ended, or `None` while it runs.
    #[getter]
    fn outcome(&self) -> Option<&'static str> {
        self.episode.env().outcome().map(outcome_name)
    }

    /// The ego: `(arc length of its front bumper in m, speed in m/s,
    /// committed)`.
    #[getter]
    fn ego(&self) -> (f64, f64, bool) {
        let e = self.episode.env().ego();
        (e.s, e.v, e.committed)
    }

    /// Smallest time to collision over the cars the ego sees, s (infinite
    /// when none comes).
    fn min_ttc(&self) -> f64 {
        self.episode.env().min_ttc(true)
    }

    fn __repr__(&self) -> String {
        let env = self.episode.env();
        format!(
            "Env(scenario={:?}, actions={:?}, observation={:?})",
            env.scenario().name(),
            env.config().action_set.name(),
            env.obs_spec().name()
        )
    }
}

/// `ObsKind` by the name Python passes.
pub(crate) fn observation_kind(name: &str) -> Option<ObsKind> {
    match name {
        "ttg" => Some(ObsKind::Ttg),
        "sequential" => Some(ObsKind::Sequential),
        _ => None,
    }
}

/// `env`'s state drawn as `crossroads render` draws it (the wide view for
/// a grid or occluders), as a `height x width x 3` uint8 array.
pub(crate) fn render<'py>(
    py: Python<'py>,
    env: &Env,
    grid: bool,
    scale: Option<f64>,
) -> PyResult<Bound<'py, numpy::PyArray3<u8>>> {
    let mut view = if grid || !env.occluders().is_empty() {
        RenderView::wide()
    } else {
        RenderView::default()
    };
    if let Some(s) = scale {
        if !(s.is_finite() && s > 0.0) {
            return Err(value_error("scale must be a positive number"));
        }
        view.scale = s;
    }
    let options = SceneOptions {
        grid: grid.then_some(env.config().observation),
    };
    let scene = Scene::of(env, &view, &options);
    let (w, h) = scene.size;
    let pixels = py
        .detach(|| crossroads_draw::rgb(&scene))
        .map_err(value_error)?;
    let image = Array3::from_shape_vec((h as usize, w as usize, 3), pixels).map_err(value_error)?;
    Ok(image.into_pyarray(py))
}
