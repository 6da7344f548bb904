//! A trained Q-network as a simulator [`Policy`]: greedy actions from one
//! batched forward pass per call, so `crossroads eval`, `render` and the
//! training run's evaluations drive it like the TTC baseline.
//!
//! It loads a checkpoint folder or a `.safetensors` file, or several joined
//! by commas as an ensemble that acts on the mean of their Q-values.
//! libtorch tensors are not `Sync`, so each rayon thread has its own copy.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

use anyhow::Context;
use crossroads_config::PrecisionSetting;
use crossroads_model::{Precision, QNetwork, WeightsMeta, Work};
use crossroads_sim::{ActionSet, Env, Policy, PolicyRng, SimError};

/// Greedy policy of a Q-network. `act` runs one forward pass for the whole
/// batch (no graph). libtorch tensors cannot be shared between threads, so
/// each evaluation thread has its own copy of the network.
#[derive(Debug)]
pub struct NetworkPolicy {
    /// Per rayon thread, the members of the policy (one network, or an
    /// ensemble whose Q-values are averaged).
    nets: Vec<Mutex<Vec<QNetwork>>>,
    spec: crossroads_model::NetworkSpec,
    name: String,
}

impl NetworkPolicy {
    /// The policy of the weights in `safetensors`, named `name` (e.g.
    /// `dqn:ckpt-000000012000@v7`), with a copy per rayon thread.
    pub fn from_safetensors(safetensors: &[u8], name: String) -> anyhow::Result<Self> {
        Self::ensemble(&[safetensors], name)
    }

    /// The policy averaging the Q-values of several networks of the same
    /// spec (e.g. checkpoints of one run), with a copy per rayon thread.
    pub fn ensemble(members: &[&[u8]], name: String) -> anyhow::Result<Self> {
        anyhow::ensure!(
            !members.is_empty(),
            "an ensemble needs at least one network"
        );
        let copies = rayon::current_num_threads().max(1);
        let nets = (0..copies)
            .map(|_| {
                members
                    .iter()
                    .map(|m| QNetwork::from_safetensors(m).map(|(net, _)| net))
                    .collect::<Result<Vec<_>, _>>()
                    .map(Mutex::new)
            })
            .collect::<Result<Vec<_>, _>>()
            .context("reading the network's weights")?;
        let first = nets[0].lock().unwrap_or_else(PoisonError::into_inner);
        let spec = first[0].spec().clone();
        for (i, net) in first.iter().enumerate().skip(1) {
            anyhow::ensure!(
                net.spec() == &spec,
                "ensemble member {} is another network than member 0 ({:?} against {:?})",
                i,
                net.spec(),
                spec
            );
        }
        drop(first);
        Ok(Self { nets, spec, name })
    }

    /// The mean Q-values of the members for `n` observations.
    fn infer(&self, obs: &[f32], n: usize) -> Result<Vec<f32>, SimError> {
        let slot = rayon::current_thread_index().unwrap_or(0) % self.nets.len();
        let members = self.nets[slot]
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let mut sum: Vec<f32> = Vec::new();
        for net in members.iter() {
            let q = net
                .infer(obs, n)
                .map_err(|e| SimError::Policy(Box::new(e)))?;
            if sum.is_empty() {
                sum = q.q;
            } else {
                sum.iter_mut().zip(&q.q).for_each(|(s, v)| *s += v);
            }
        }
        if members.len() > 1 {
            let k = members.len() as f32;
            sum.iter_mut().for_each(|s| *s /= k);
        }
        Ok(sum)
    }

    /// Loads the network of `path`: a checkpoint folder (its
    /// `weights.safetensors`) or a `.safetensors` file; several of them
    /// joined by commas make an ensemble that averages their Q-values (see
    /// [`NetworkPolicy::load_members`]). `None` when `path` names none of
    /// these (so a policy string like `ttc:2` is parsed instead).
    pub fn load(path: &Path) -> anyhow::Result<Option<Self>> {
        let text = path.to_string_lossy();
        if text.contains(',') {
            let members: Vec<PathBuf> = text.split(',').map(PathBuf::from).collect();
            return Self::load_members(&members).map(Some);
        }
        let Some((bytes, label)) = read_weights(path, false)? else {
            return Ok(None);
        };
        Self::from_safetensors(&bytes, format!("dqn:{label}")).map(Some)
    }

    /// The ensemble of the networks in `paths` (checkpoint folders or
    /// weights files of the same spec, e.g. the best weights of runs
    /// trained from different seeds): it acts greedily on the mean of their
    /// Q-values. Independently trained networks misjudge different rare
    /// states, so their mean makes fewer such mistakes than either
    /// (reports/paper/NOTES.md).
    pub fn load_members(paths: &[PathBuf]) -> anyhow::Result<Self> {
        let mut bytes = Vec::with_capacity(paths.len());
        let mut labels = Vec::with_capacity(paths.len());
        for path in paths {
            let (b, label) = read_weights(path, paths.len() > 1)?.with_context(|| {
                format!(
                    "ensemble member {} is no checkpoint folder or weights file",
                    path.display()
                )
            })?;
            bytes.push(b);
            labels.push(label);
        }
        if let [one] = bytes.as_slice() {
            return Self::from_safetensors(one, format!("dqn:{}", labels[0]));
        }
        let members: Vec<&[u8]> = bytes.iter().map(Vec::as_slice).collect();
        Self::ensemble(&members, format!("dqn-mean:{}", labels.join("+")))
    }

    /// Computes every copy's trunk in the format `setting` chooses for
    /// this network (fp32 after loading).
    pub fn set_precision(&mut self, setting: PrecisionSetting) {
        let precision = Precision::choose(setting, &self.spec, Work::Acting);
        if precision != Precision::F32 {
            self.name = format!("{} ({precision})", self.name.trim_end_matches(" (bf16)"));
        }
        for copies in &mut self.nets {
            let members = copies.get_mut().unwrap_or_else(PoisonError::into_inner);
            for net in members.iter_mut() {
                net.set_precision(precision);
            }
        }
    }

    /// The network's spec.
    pub fn spec(&self) -> &crossroads_model::NetworkSpec {
        &self.spec
    }

    /// Checks that the network reads what `env` observes; an error names
    /// both layouts.
    pub fn fits(&self, env: &Env) -> anyhow::Result<()> {
        let ours = &self.spec.observation;
        let given = env.obs_spec().layout();
        anyhow::ensure!(
            &given == ours,
            "the network reads {} observations ({ours}, {} values); scenario {} with these actions gives {given} ({} values)",
            ours.kind,
            ours.len(),
            env.scenario().name(),
            given.len(),
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
        let q = self.infer(&obs, envs.len())?;
        let k = self.spec.num_actions as usize;
        for (a, row) in actions.iter_mut().zip(q.chunks_exact(k)) {
            *a = crossroads_actor::argmax(row);
        }
        Ok(())
    }

    fn values(&self, env: &Env) -> Result<Option<Vec<f32>>, SimError> {
        let mut obs = vec![0.0f32; self.spec.input_len() as usize];
        env.write_observation(&mut obs)?;
        Ok(Some(self.infer(&obs, 1)?))
    }
}

/// The bytes of the weights at `path` (a checkpoint folder or a
/// `.safetensors` file) and a label naming them with their version; `None`
/// when `path` is neither. With `run_label`, a run's `best/` (or `last/`,
/// or a checkpoint) is named with its run's folder.
fn read_weights(path: &Path, run_label: bool) -> anyhow::Result<Option<(Vec<u8>, String)>> {
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
    // The header only: the networks are built once, per thread, later.
    let version = WeightsMeta::read(&bytes)
        .with_context(|| format!("{} holds no network weights", file.display()))?
        .version;
    let label = if file.file_name().is_some_and(|n| n == "weights.safetensors") {
        if run_label {
            folder_label(path)
        } else {
            path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            )
        }
    } else {
        file.display().to_string()
    };
    Ok(Some((bytes, format!("{label}@v{version}"))))
}

/// `best`, `last` and `checkpoints/ckpt-...` folders are named with their
/// run's folder (`ttg-left/best`) when it is in the path; other folders by
/// their own name.
fn folder_label(path: &Path) -> String {
    let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
    let Some(own) = name(path) else {
        return path.display().to_string();
    };
    let run = match own.as_str() {
        "best" | "last" => path.parent().and_then(name),
        _ if own.starts_with("ckpt-") => path.parent().and_then(Path::parent).and_then(name),
        _ => None,
    };
    run.map_or(own.clone(), |r| format!("{r}/{own}"))
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use crossroads_model::{NetworkSpec, TrunkKind};
    use crossroads_sim::{EnvConfig, Scenario};

    use super::*;

    fn ttg() -> crossroads_model::ObservationLayout {
        crossroads_sim::observation_layout("ttg").expect("a view")
    }

    fn weights(seed: u64) -> Vec<u8> {
        let spec = NetworkSpec::new(ttg(), "ttg", TrunkKind::Mlp, vec![8, 8]).expect("spec");
        QNetwork::new(spec, seed)
            .and_then(|n| n.to_safetensors(seed))
            .expect("network")
    }

    fn env() -> Env {
        let sc = Arc::new(Scenario::load("left").expect("scenario"));
        let mut env = Env::new(sc, EnvConfig::for_actions(ActionSet::Ttg));
        env.reset(4);
        env
    }

    #[test]
    fn an_ensemble_acts_on_the_mean_of_its_members_q_values() {
        let (a, b) = (weights(1), weights(2));
        let env = env();
        let qa = NetworkPolicy::from_safetensors(&a, "a".into())
            .and_then(|p| Ok(p.values(&env)?.expect("values")))
            .expect("member a");
        let qb = NetworkPolicy::from_safetensors(&b, "b".into())
            .and_then(|p| Ok(p.values(&env)?.expect("values")))
            .expect("member b");
        assert_ne!(qa, qb, "two seeds, two networks");
        let mean = NetworkPolicy::ensemble(&[&a, &b], "mean".into())
            .and_then(|p| Ok(p.values(&env)?.expect("values")))
            .expect("ensemble");
        for ((m, x), y) in mean.iter().zip(&qa).zip(&qb) {
            assert!(
                (m - (x + y) / 2.0).abs() < 1e-6,
                "{mean:?} from {qa:?} and {qb:?}"
            );
        }
        let twice = NetworkPolicy::ensemble(&[&a, &a], "a twice".into())
            .and_then(|p| Ok(p.values(&env)?.expect("values")))
            .expect("ensemble");
        for (t, x) in twice.iter().zip(&qa) {
            assert!((t - x).abs() < 1e-6, "{twice:?} against {qa:?}");
        }
    }

    #[test]
    fn an_ensemble_of_different_networks_is_refused_naming_the_member() {
        let spec = NetworkSpec::new(ttg(), "ttg", TrunkKind::Mlp, vec![8, 4]).expect("spec");
        let other = QNetwork::new(spec, 3)
            .and_then(|n| n.to_safetensors(1))
            .expect("network");
        let err = NetworkPolicy::ensemble(&[&weights(1), &other], "mixed".into())
            .expect_err("different networks");
        assert!(format!("{err:#}").contains("member 1"), "{err:#}");
    }

    #[test]
    fn load_reads_comma_joined_paths_as_one_ensemble() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (a, b) = (
            dir.path().join("a.safetensors"),
            dir.path().join("b.safetensors"),
        );
        std::fs::write(&a, weights(1)).expect("write a");
        std::fs::write(&b, weights(2)).expect("write b");
        let joined = format!("{},{}", a.display(), b.display());
        let policy = NetworkPolicy::load(Path::new(&joined))
            .expect("load")
            .expect("a network");
        assert!(policy.name().starts_with("dqn-mean:"), "{}", policy.name());
        let missing = format!("{},{}", a.display(), dir.path().join("none").display());
        let err = NetworkPolicy::load(Path::new(&missing)).expect_err("a missing member");
        assert!(format!("{err:#}").contains("none"), "{err:#}");
    }
}
