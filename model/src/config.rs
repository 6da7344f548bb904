//! The network a run's configuration describes.

use crossroads_config::{LearnerConfig, SimConfig};

use crate::ModelError;
use crate::spec::NetworkSpec;

/// The network `[sim]` (observation layout, action set) and `[learner]`
/// (trunk, hidden sizes) describe: the learner trains it and actors start
/// from it, built with `learner.seed`. The layout must be resolved (every
/// role does at start, `crossroads_actor::resolve_observation`).
pub fn network_spec(sim: &SimConfig, c: &LearnerConfig) -> Result<NetworkSpec, ModelError> {
    let layout = sim.layout().ok_or_else(|| {
        ModelError::Spec(
            "the layout of sim.observation is unresolved: a role derives it from \
             sim.scenario and sim.action_set at start (crossroads_actor::resolve_observation)"
                .to_owned(),
        )
    })?;
    let hidden = c.hidden.iter().map(|&h| i64::from(h)).collect();
    Ok(NetworkSpec::new(
        layout.clone(),
        &sim.action_set,
        c.trunk,
        hidden,
    )?)
}
