//! The oracle: the top of the ladder a policy that sees only the ego's
//! view is measured against.

use rand::RngExt;

use super::{Policy, PolicyRng, shield_fallback};
use crate::action::ActionSet;
use crate::env::{Env, Outcome};
use crate::error::SimError;
use crate::seed::episode_seed;

/// Goes when going now reaches the goal in every one of `futures` forks of
/// the environment ([`Env::fork`]: the same present, hidden cars included,
/// other random traffic from then on); otherwise creeps while the creep
/// limit is ahead (creep actions) or waits one step, as the shield alone
/// does ([`shield_fallback`]). It knows what no sensor shows (cars behind the walls)
/// and tries each *go* before taking it, so it bounds from above what a
/// policy with the same creep profile can reach on the same trials. It can
/// still collide: a future none of its forks drew.
///
/// Cost: up to `futures` simulated crossings per decision (a fork stops at
/// its first collision, and the oracle at its first fork that fails).
/// The forks' seeds come from the environment's policy generator, so an
/// episode's decisions depend only on its seed.
/// Why the oracle needs a final *go*.
const WHY: &str = "it tries a final go";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OraclePolicy {
    futures: u32,
}

impl OraclePolicy {
    /// The oracle trying `futures` forks (at least 1) per decision.
    pub fn new(futures: u32) -> Self {
        Self {
            futures: futures.max(1),
        }
    }

    fn go_is_safe(&self, env: &Env, go: usize, rng: &mut PolicyRng) -> Result<bool, SimError> {
        let base: u64 = rng.random();
        for j in 0..self.futures {
            let mut fork = env.fork(episode_seed(base, u64::from(j)));
            fork.step(go)?;
            if fork.metrics().outcome != Some(Outcome::Success) {
                return Ok(false);
            }
        }
        Ok(true)
    }
}

impl Policy for OraclePolicy {
    fn name(&self) -> String {
        format!("oracle:{}", self.futures)
    }

    fn supports(&self, set: ActionSet) -> Result<(), SimError> {
        set.final_go_for(&self.name(), WHY).map(|_| ())
    }

    fn act(
        &self,
        envs: &[Env],
        rngs: &mut [PolicyRng],
        actions: &mut [usize],
    ) -> Result<(), SimError> {
        for ((env, rng), a) in envs.iter().zip(rngs.iter_mut()).zip(actions.iter_mut()) {
            let set = env.config().action_set;
            let go = set.final_go_for(&self.name(), WHY)?;
            *a = if env.ego().committed || self.go_is_safe(env, go, rng)? {
                go
            } else {
                shield_fallback(env, go, None)
            };
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::eval::{EvalConfig, evaluate};
    use crate::policy::{ShieldedPolicy, TtcPolicy};
    use crate::scenario::Scenario;
    use crate::shield::ShieldParams;

    fn occluded() -> Arc<Scenario> {
        Arc::new(Scenario::builtin("occluded-30").expect("built-in scenario"))
    }

    #[test]
    fn the_oracle_succeeds_at_least_as_often_as_the_shield_alone_and_seldom_collides() {
        let sc = occluded();
        let config = EvalConfig::new(ActionSet::Creep, 200, 3);
        let oracle = evaluate(&sc, &OraclePolicy::new(8), &config, &|_| {}).unwrap();
        let shield = ShieldedPolicy::new(
            Box::new(TtcPolicy::new(0.0, false)),
            ShieldParams::default(),
        );
        let alone = evaluate(&sc, &shield, &config, &|_| {}).unwrap();
        assert!(
            oracle.success_rate >= alone.success_rate,
            "oracle {} against the shield alone {}",
            oracle.success_rate,
            alone.success_rate
        );
        assert!(oracle.collision_rate <= 0.02, "{}", oracle.collision_rate);
    }

    #[test]
    fn the_oracle_drives_the_same_on_every_run() {
        let sc = occluded();
        let config = EvalConfig::new(ActionSet::Creep, 40, 11);
        let a = evaluate(&sc, &OraclePolicy::new(4), &config, &|_| {}).unwrap();
        let b = evaluate(&sc, &OraclePolicy::new(4), &config, &|_| {}).unwrap();
        assert_eq!(a.success_rate, b.success_rate);
        assert_eq!(a.collision_rate, b.collision_rate);
        assert_eq!(a.mean_time_s, b.mean_time_s);
    }

    #[test]
    fn the_oracle_refuses_sequential_actions() {
        let err = OraclePolicy::new(4)
            .supports(ActionSet::Sequential)
            .unwrap_err()
            .to_string();
        assert!(err.contains("oracle:4"), "{err}");
    }
}
