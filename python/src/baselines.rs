//! The rule baselines, as callables on an environment's present state:
//! `Ttc` (with or without creeping) chooses an action, `Shield` vets one.
//! Both are the policies `crossroads eval` runs (`--policy ttc:T`,
//! `ttc-creep:T`, `--shield`), so they choose exactly what it chooses.

use crossroads_sim::{
    Env, Policy, PolicyRng, SensedCar, ShieldParams, TtcPolicy, check_go, sense, shield_fallback,
};
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use rand::SeedableRng;

use crate::env::PyEnv;
use crate::value_error;
use crate::vec_env::PyVecEnv;

/// The time-to-collision rule: go when every car the ego sees is more
/// than `threshold` seconds from its path; with `creep`, first creep until
/// the conflicting lanes are in view (creep and sequential actions).
#[pyclass(module = "crossroads._native", name = "Ttc", frozen)]
#[derive(Debug)]
pub struct PyTtc {
    policy: TtcPolicy,
}

impl PyTtc {
    fn act(&self, env: &Env) -> PyResult<usize> {
        self.policy
            .supports(env.config().action_set)
            .map_err(value_error)?;
        // The rule draws nothing; the stream is there for the trait.
        let mut rng = [PolicyRng::seed_from_u64(0)];
        let mut action = [0];
        self.policy
            .act(std::slice::from_ref(env), &mut rng, &mut action)
            .map_err(value_error)?;
        Ok(action[0])
    }
}

#[pymethods]
impl PyTtc {
    #[new]
    #[pyo3(signature = (threshold=1.5, creep=false))]
    fn new(threshold: f64, creep: bool) -> PyResult<Self> {
        if !(threshold.is_finite() && threshold >= 0.0) {
            return Err(value_error(
                "threshold must be finite seconds, zero or more",
            ));
        }
        Ok(Self {
            policy: TtcPolicy::new(threshold, creep),
        })
    }

    /// The action for `env`'s present state.
    fn __call__(&self, env: PyRef<'_, PyEnv>) -> PyResult<usize> {
        self.act(env.episode.env())
    }

    /// One action per environment of `envs`.
    fn batch<'py>(
        &self,
        py: Python<'py>,
        envs: PyRef<'py, PyVecEnv>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let mut out = Vec::with_capacity(envs.len());
        for i in 0..envs.len() {
            if let Some(ep) = envs.episode(i) {
                out.push(self.act(ep.env())? as i64);
            }
        }
        Ok(out.into_pyarray(py))
    }

    /// `ttc:T` or `ttc-creep:T`, as `crossroads eval --policy` spells it.
    #[getter]
    fn name(&self) -> String {
        self.policy.name()
    }

    fn __repr__(&self) -> String {
        format!("Ttc({})", self.policy.name())
    }
}

/// The safety shield: a *go* it cannot prove safe becomes a one-step
/// creep or wait (ttg and creep actions). `assumptions` as `crossroads
/// eval --shield` takes them: `default`, or `key=value,...`.
#[pyclass(module = "crossroads._native", name = "Shield")]
#[derive(Debug)]
pub struct PyShield {
    params: ShieldParams,
    sensed: Vec<SensedCar>,
    go_decisions: u64,
    vetoes: u64,
}

impl PyShield {
    fn filter_one(&mut self, env: &Env, action: usize) -> PyResult<usize> {
        let set = env.config().action_set;
        let go = set
            .final_go_for("the shield", "it checks a final go")
            .map_err(value_error)?;
        if action != go || env.ego().committed {
            return Ok(action);
        }
        self.go_decisions += 1;
        sense(env, &self.params, &mut self.sensed);
        if check_go(env, &self.sensed, &self.params).is_some() {
            self.vetoes += 1;
            return Ok(shield_fallback(env, go, None));
        }
        Ok(action)
    }
}

#[pymethods]
impl PyShield {
    #[new]
    #[pyo3(signature = (assumptions="default"))]
    fn new(assumptions: &str) -> PyResult<Self> {
        Ok(Self {
            params: ShieldParams::parse(assumptions).map_err(value_error)?,
            sensed: Vec::new(),
            go_decisions: 0,
            vetoes: 0,
        })
    }

    /// `action`, or what replaces it when it is a *go* the shield vetoes.
    fn __call__(&mut self, env: PyRef<'_, PyEnv>, action: usize) -> PyResult<usize> {
        self.filter_one(env.episode.env(), action)
    }

    /// `actions[i]` vetted in environment `i` of `envs`.
    fn batch<'py>(
        &mut self,
        py: Python<'py>,
        envs: PyRef<'py, PyVecEnv>,
        actions: PyReadonlyArray1<'py, i64>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let actions = actions.as_slice().map_err(value_error)?;
        if actions.len() != envs.len() {
            return Err(value_error(format!(
                "{} actions for {} environments",
                actions.len(),
                envs.len()
            )));
        }
        let mut out = Vec::with_capacity(actions.len());
        for (i, &a) in actions.iter().enumerate() {
            let a = usize::try_from(a).map_err(value_error)?;
            if let Some(ep) = envs.episode(i) {
                out.push(self.filter_one(ep.env(), a)? as i64);
            }
        }
        Ok(out.into_pyarray(py))
    }

    /// *Go* decisions checked so far.
    #[getter]
    fn go_decisions(&self) -> u64 {
        self.go_decisions
    }

    /// Of those, vetoed.
    #[getter]
    fn vetoes(&self) -> u64 {
        self.vetoes
    }
}
