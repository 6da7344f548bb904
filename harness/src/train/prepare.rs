//! Before a session starts: the run folder checked (a run already there
//! needs `--resume`), the configuration derived for a local run (the
//! transports, the folder's checkpoints and snapshots) and written to `config.toml`, and the previous sessions'
//! summary read.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use crossroads_config::{ActorTransport, Config};
use crossroads_sim::{ActionSet, Scenario};

use super::record::{Summary, write_atomic};

/// A run ready to start: its folder and its configuration.
pub struct Run {
    pub out: PathBuf,
    pub config: Config,
    pub scenario: Arc<Scenario>,
    pub actions: ActionSet,
    pub previous: Summary,
}

/// Checks the folder, derives a local run's settings and writes
/// `config.toml` (with the observation the command resolved).
pub fn prepare(config: &Config, out: &Path, resume: bool) -> anyhow::Result<Run> {
    let mut c = config.clone();
    let scenario = Arc::new(
        Scenario::load_with_drivers(&c.sim.scenario, c.sim.drivers.as_deref()).with_context(
            || {
                format!(
                    "sim.scenario {:?}, sim.drivers {:?}",
                    c.sim.scenario, c.sim.drivers
                )
            },
        )?,
    );
    let actions: ActionSet = c
        .sim
        .action_set
        .parse()
        .with_context(|| format!("sim.action_set {:?}", c.sim.action_set))?;
    // `sim.observation` was resolved when the command loaded the config.
    c.actor.index = None;
    c.actor.eval = false;
    c.actor.transport = c.train.transport;
    c.actor.weights = Some(c.train.transport);
    let shm = c.train.transport == ActorTransport::Shm;
    c.replay.shm_ingest = shm;
    c.learner.shm_publish = shm;

    let has_checkpoints = out
        .join("checkpoints")
        .read_dir()
        .is_ok_and(|mut d| d.next().is_some());
    anyhow::ensure!(
        resume || !has_checkpoints,
        "{} already holds a run; add --resume to continue it, or choose another --out",
        out.display()
    );
    std::fs::create_dir_all(out.join("logs"))
        .with_context(|| format!("creating {}", out.display()))?;
    let out = out
        .canonicalize()
        .with_context(|| format!("resolving {}", out.display()))?;
    c.learner.checkpoint_dir = Some(out.join("checkpoints"));
    c.learner.resume = resume;
    c.replay.snapshot_dir = Some(out.join("replay"));
    c.replay.restore = resume;
    let problems = c.validate();
    anyhow::ensure!(
        problems.is_empty(),
        "invalid run configuration: {}",
        problems
            .iter()
            .map(|(k, p)| format!("{k}: {p}"))
            .collect::<Vec<_>>()
            .join("; ")
    );
    write_atomic(&out.join("config.toml"), c.to_toml().as_bytes())?;
    let previous = if resume {
        Summary::load(&out)?.unwrap_or_default()
    } else {
        for stale in ["curve.csv", "summary.json"] {
            let _ = std::fs::remove_file(out.join(stale));
        }
        Summary::default()
    };
    Ok(Run {
        out,
        config: c,
        scenario,
        actions,
        previous,
    })
}
