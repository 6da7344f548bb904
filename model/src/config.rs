//! The network a run's configuration describes.

use crossroads_config::{LearnerConfig, Trunk};

use crate::ModelError;
use crate::spec::{NetworkSpec, TrunkKind};

/// The network `[learner]` describes (observation, action set, trunk,
/// hidden sizes): the learner trains it and actors start from it, built
/// with `learner.seed`.
pub fn network_spec(c: &LearnerConfig) -> Result<NetworkSpec, ModelError> {
    let trunk = match c.trunk {
        Trunk::Mlp => TrunkKind::Mlp,
        Trunk::Conv => TrunkKind::Conv,
    };
    let hidden = c.hidden.iter().map(|&h| i64::from(h)).collect();
    Ok(NetworkSpec::new(
        &c.observation,
        &c.action_set,
        trunk,
        hidden,
    )?)
}
