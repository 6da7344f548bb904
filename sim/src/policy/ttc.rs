//! The time-to-collision baseline, with and without creeping.

use super::{Policy, PolicyRng, act_by_intent};
use crate::action::{ActionSet, Intent};
use crate::env::Env;
use crate::error::SimError;

/// Go when every car the ego sees will take longer than `threshold` seconds
/// (at constant speed) to reach the ego's path. With `creep`, first creep
/// until the conflicting lanes are visible far enough upstream (as far as a
/// car at 1.5 times the speed limit covers in `threshold`, so fast cars are
/// seen too), or until the creep limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TtcPolicy {
    threshold: f64,
    creep: bool,
}

impl TtcPolicy {
    /// The rule with this threshold, in seconds.
    pub fn new(threshold: f64, creep: bool) -> Self {
        Self { threshold, creep }
    }

    /// What the rule wants for one environment.
    pub fn intent(&self, env: &Env) -> Intent {
        let sc = env.scenario();
        let e = &sc.spec().ego;
        let ego = env.ego();
        // Once on its way (TTG or Creep go, or accelerating past creep speed
        // with sequential actions), TTC does not stop in the intersection.
        if ego.committed || ego.v > e.params.creep_speed + 0.5 {
            return Intent::Go;
        }
        if self.creep && ego.s < e.creep_limit_s - 0.05 {
            let range = 1.5 * self.threshold * sc.spec().speed_limit;
            if !env.sees_conflicts(range) {
                return Intent::Creep;
            }
        }
        if env.min_ttc(true) > self.threshold {
            Intent::Go
        } else {
            Intent::Wait
        }
    }
}

impl Policy for TtcPolicy {
    fn name(&self) -> String {
        if self.creep {
            format!("ttc-creep:{}", self.threshold)
        } else {
            format!("ttc:{}", self.threshold)
        }
    }

    fn supports(&self, set: ActionSet) -> Result<(), SimError> {
        if self.creep && set == ActionSet::Ttg {
            return Err(SimError::Unsupported {
                policy: self.name(),
                set: set.name(),
            });
        }
        Ok(())
    }

    fn act(
        &self,
        envs: &[Env],
        _rngs: &mut [PolicyRng],
        actions: &mut [usize],
    ) -> Result<(), SimError> {
        act_by_intent(self, envs, actions, |env| self.intent(env))
    }
}
