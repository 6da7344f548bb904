//! The random policy: every action of the set equally likely.

use rand::RngExt;

use super::{Policy, PolicyRng};
use crate::action::ActionSet;
use crate::env::Env;
use crate::error::SimError;

/// Uniform over the action set's indices.
#[derive(Debug, Clone, Copy, Default)]
pub struct RandomPolicy;

impl Policy for RandomPolicy {
    fn name(&self) -> String {
        "random".to_owned()
    }

    fn supports(&self, _set: ActionSet) -> Result<(), SimError> {
        Ok(())
    }

    fn act(
        &self,
        envs: &[Env],
        rngs: &mut [PolicyRng],
        actions: &mut [usize],
    ) -> Result<(), SimError> {
        for ((env, rng), a) in envs.iter().zip(rngs.iter_mut()).zip(actions.iter_mut()) {
            *a = rng.random_range(0..env.config().action_set.num_actions());
        }
        Ok(())
    }
}
