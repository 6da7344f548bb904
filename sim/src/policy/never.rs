//! The policy that never goes: the ego waits at the stop line until the
//! time limit. It measures the traffic alone (its braking with no ego to
//! react to).

use super::{Policy, PolicyRng};
use crate::action::{ActionSet, Intent};
use crate::env::Env;
use crate::error::SimError;

/// Always *wait*.
#[derive(Debug, Clone, Copy, Default)]
pub struct NeverPolicy;

impl Policy for NeverPolicy {
    fn name(&self) -> String {
        "never".to_owned()
    }

    fn supports(&self, _set: ActionSet) -> Result<(), SimError> {
        Ok(())
    }

    fn act(
        &self,
        envs: &[Env],
        _rngs: &mut [PolicyRng],
        actions: &mut [usize],
    ) -> Result<(), SimError> {
        for (env, a) in envs.iter().zip(actions.iter_mut()) {
            let p = &env.scenario().spec().ego.params;
            *a = env
                .config()
                .action_set
                .encode(Intent::Wait, env.ego().v, p.creep_speed)
                .ok_or_else(|| SimError::Unsupported {
                    policy: self.name(),
                    set: env.config().action_set.name(),
                })?;
        }
        Ok(())
    }
}
