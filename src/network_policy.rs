//! A trained Q-network as a simulator [`Policy`]: greedy actions from one
//! batched forward pass per call, so `crossroads eval`, `render` and the
//! training run's evaluations drive it like the TTC baseline.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

use anyhow::Context;
use crossroads_model::QNetwork;
use crossroads_sim::{ActionSet, Env, Policy, PolicyRng, SimError};

/// Greedy policy of a Q-network. `act` runs one forward pass for the whole
/// batch (no graph). libtorch tensors cannot be shared between threads, so
/// each evaluation thread has its own copy of the network.
#[derive(Debug)]
pub struct NetworkPolicy {
    nets: Vec<Mutex<QNetwork>>,
    spec: crossroads_model::NetworkSpec,
    name: String,
}

impl NetworkPolicy {
    /// The policy of the weights in `safetensors`, named `name` (e.g.
    /// `dqn:ckpt-000000012000@v7`), with a copy per rayon thread.
    pub fn from_safetensors(safetensors: &[u8], name: String) -> anyhow::Result<Self> {
        let copies = rayon::current_num_threads().max(1);
        let nets = (0..copies)
            .map(|_| QNetwork::from_safetensors(safetensors).map(|(net, _)| Mutex::new(net)))
            .collect::<Result<Vec<_>, _>>()
            .context("reading the network's weights")?;
        let spec = nets[0]
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .spec()
            .clone();
        Ok(Self { nets, spec, name })
    }

    /// Loads the network of `path`: a checkpoint folder (its
    /// `weights.safetensors`) or a `.safetensors` file. `None` when `path`
    /// names neither (so a policy string like `ttc:2` is parsed instead).
    pub fn load(path: &Path) -> anyhow::Result<Option<Self>> {
        let file: PathBuf = if path.is_dir() {
            let f = path.join("weights.safetensors");
            anyhow::ensure!(
                f.is_file(),
                "{} is a folder without weights.safetensors (not a checkpoint)",
                path.display()
            );
            f
        } else if path.is_file() {
            path.to_path_buf()
        } else {
            return Ok(None);
        };
        let bytes = std::fs::read(&file).with_context(|| format!("reading {}", file.display()))?;
        let (_, version) = QNetwork::from_safetensors(&bytes)
            .with_context(|| format!("{} holds no network weights", file.display()))?;
        let label = if file.file_name().is_some_and(|n| n == "weights.safetensors") {
            path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            )
        } else {
            file.display().to_string()
        };
        Self::from_safetensors(&bytes, format!("dqn:{label}@v{version}")).map(Some)
    }

    /// The network's spec.
    pub fn spec(&self) -> &crossroads_model::NetworkSpec {
        &self.spec
    }

    /// Checks that the network reads what `env` observes; an error names
    /// both shapes.
    pub fn fits(&self, env: &Env) -> anyhow::Result<()> {
        let spec = &self.spec;
        let len = env.obs_spec().len();
        anyhow::ensure!(
            spec.input_len() as usize == len,
            "the network reads {} observations of {} values; scenario {} with these actions gives {len}",
            spec.observation.kind,
            spec.input_len(),
            env.scenario().name(),
        );
        Ok(())
    }
}

impl Policy for NetworkPolicy {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn supports(&self, set: ActionSet) -> Result<(), SimError> {
        let spec = &self.spec;
        if spec.action_set == set.name() && spec.num_actions as usize == set.num_actions() {
            Ok(())
        } else {
            Err(SimError::Unsupported {
                policy: format!("{} (trained for {} actions)", self.name, spec.action_set),
                set: set.name(),
            })
        }
    }

    fn act(
        &self,
        envs: &[Env],
        _rngs: &mut [PolicyRng],
        actions: &mut [usize],
    ) -> Result<(), SimError> {
        let len = self.spec.input_len() as usize;
        let mut obs = vec![0.0f32; envs.len() * len];
        for (env, out) in envs.iter().zip(obs.chunks_exact_mut(len)) {
            env.write_observation(out)?;
        }
        let slot = rayon::current_thread_index().unwrap_or(0) % self.nets.len();
        let q = self.nets[slot]
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .infer(&obs, envs.len())
            .map_err(|e| SimError::Policy(Box::new(e)))?;
        for (i, a) in actions.iter_mut().enumerate() {
            *a = crossroads_actor::argmax(q.row(i));
        }
        Ok(())
    }

    fn values(&self, env: &Env) -> Result<Option<Vec<f32>>, SimError> {
        let mut obs = vec![0.0f32; self.spec.input_len() as usize];
        env.write_observation(&mut obs)?;
        let slot = rayon::current_thread_index().unwrap_or(0) % self.nets.len();
        let q = self.nets[slot]
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .infer(&obs, 1)
            .map_err(|e| SimError::Policy(Box::new(e)))?;
        Ok(Some(q.row(0).to_vec()))
    }
}
