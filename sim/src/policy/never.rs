//! Policies of one intent. [`NeverPolicy`] never goes: the ego waits at
//! the stop line until the time limit, which measures the traffic alone
//! (its braking with no ego to react to). [`GoPolicy`] wants to go at
//! every decision: behind the shield, the shield alone in its plainest
//! form (go whenever it allows, else its fallback: creep to the limit,
//! then wait).

use super::{Policy, PolicyRng, act_by_intent};
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
        act_by_intent(self, envs, actions, |_| Intent::Wait)
    }
}

/// Always *go* (`go`). Alone it crosses at once; behind the shield
/// ([`crate::ShieldedPolicy`]) every decision asks the shield, so the ego
/// goes at the first moment the shield allows and creeps or waits by the
/// shield's fallback until then. `ttc-creep:0` behind the shield differs:
/// its rule stands still while a car it sees is in a conflict zone
/// (time to collision 0), where this creeps on.
#[derive(Debug, Clone, Copy, Default)]
pub struct GoPolicy;

impl Policy for GoPolicy {
    fn name(&self) -> String {
        "go".to_owned()
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
        act_by_intent(self, envs, actions, |_| Intent::Go)
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

    #[test]
    fn go_behind_the_shield_creeps_on_where_ttc_creep_zero_stands() {
        // The same 300 trials of occluded-30, behind the same shield: the
        // TTC rule at 0 s stands while a car it sees is in a conflict zone,
        // so it reaches the creep limit later and sees less; `go` creeps
        // on and gets through more often. Neither collides.
        let sc = Arc::new(Scenario::builtin("occluded-30").expect("built-in scenario"));
        let config = EvalConfig::new(ActionSet::Creep, 300, 7);
        let shielded = |inner: Box<dyn Policy>| ShieldedPolicy::new(inner, ShieldParams::default());
        let go = evaluate(&sc, &shielded(Box::new(GoPolicy)), &config, &|_| {}).unwrap();
        let ttc = shielded(Box::new(TtcPolicy::new(0.0, true)));
        let ttc = evaluate(&sc, &ttc, &config, &|_| {}).unwrap();
        assert_eq!(go.collision_rate, 0.0);
        assert_eq!(ttc.collision_rate, 0.0);
        assert!(
            go.success_rate > ttc.success_rate + 0.03,
            "go {} against ttc-creep:0 {}",
            go.success_rate,
            ttc.success_rate
        );
    }

    #[test]
    fn go_alone_goes_at_once() {
        let sc = Arc::new(Scenario::builtin("left").expect("built-in scenario"));
        let env = Env::new(sc, crate::env::EnvConfig::for_actions(ActionSet::Ttg));
        let mut a = [9];
        GoPolicy
            .act(std::slice::from_ref(&env), &mut [], &mut a)
            .expect("acts");
        assert_eq!(Some(a[0]), ActionSet::Ttg.absorbing_go());
    }
}
