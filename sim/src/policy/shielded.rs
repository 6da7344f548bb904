//! A policy behind the safety shield ([`crate::shield`]): every *go* it
//! chooses is checked first, and a vetoed one becomes the policy's best
//! other action (by its values when it has them, else waiting one step, or
//! creeping while the creep limit is ahead).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use super::{Policy, PolicyRng};
use crate::action::{ActionSet, Control};
use crate::env::Env;
use crate::error::SimError;
use crate::shield::{SensedCar, ShieldParams, Threat, ThreatKind, check_go, sense};

/// How often the shield was asked and how often it said no.
#[derive(Debug, Default)]
pub struct ShieldCounters {
    go_decisions: AtomicU64,
    vetoes: AtomicU64,
    phantom_vetoes: AtomicU64,
    /// Vetoes by [`ThreatKind`]: crossing, ahead, behind.
    by_kind: [AtomicU64; 3],
}

/// A snapshot of [`ShieldCounters`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct ShieldStats {
    /// *Go* decisions the policy took and the shield checked.
    pub go_decisions: u64,
    /// Of those, vetoed.
    pub vetoes: u64,
    /// Of the vetoes, those whose threat was a phantom (a car the ego
    /// could not see).
    pub phantom_vetoes: u64,
    /// Of the vetoes, those for a car on a lane the ego crosses.
    pub crossing: u64,
    /// Of the vetoes, those for a car ahead in the lane the ego turns into.
    pub ahead: u64,
    /// Of the vetoes, those for a car behind in the lane the ego turns into.
    pub behind: u64,
}

impl ShieldCounters {
    /// The counts so far.
    pub fn stats(&self) -> ShieldStats {
        ShieldStats {
            go_decisions: self.go_decisions.load(Ordering::Relaxed),
            vetoes: self.vetoes.load(Ordering::Relaxed),
            phantom_vetoes: self.phantom_vetoes.load(Ordering::Relaxed),
            crossing: self.by_kind[0].load(Ordering::Relaxed),
            ahead: self.by_kind[1].load(Ordering::Relaxed),
            behind: self.by_kind[2].load(Ordering::Relaxed),
        }
    }
}

/// `inner` behind the shield.
#[derive(Debug)]
pub struct ShieldedPolicy {
    inner: Box<dyn Policy>,
    params: ShieldParams,
    counters: Arc<ShieldCounters>,
}

impl ShieldedPolicy {
    /// Wraps `inner`.
    pub fn new(inner: Box<dyn Policy>, params: ShieldParams) -> Self {
        Self {
            inner,
            params,
            counters: Arc::default(),
        }
    }

    /// The counters, shared: read them after an evaluation.
    pub fn counters(&self) -> Arc<ShieldCounters> {
        Arc::clone(&self.counters)
    }

    /// What the shield says about *go* in `env` now: `None` when it lets
    /// it pass. The sensed cars and phantoms are left in `cars`.
    pub fn check(&self, env: &Env, cars: &mut Vec<SensedCar>) -> Option<Threat> {
        sense(env, &self.params, cars);
        check_go(env, cars, &self.params)
    }

    /// The action that replaces a vetoed *go* ([`shield_fallback`], by the
    /// inner policy's values when it has them).
    fn fallback(&self, env: &Env, go: usize) -> Result<usize, SimError> {
        let q = self.inner.values(env)?;
        Ok(shield_fallback(env, go, q.as_deref()))
    }
}

/// The action that replaces a vetoed *go* (index `go`) in `env`: the best
/// one-step alternative by `q` (a network's values, one per action) when
/// given; else creeping while the creep limit is ahead, or waiting one
/// step; so that the ego can go again as soon as the shield lets it.
pub fn shield_fallback(env: &Env, go: usize, q: Option<&[f32]>) -> usize {
    let set = env.config().action_set;
    let one_step: Vec<usize> = (0..set.num_actions())
        .filter(|&a| a != go && matches!(set.decode(a), Ok(Control::Wait(1) | Control::Creep)))
        .collect();
    if let Some(q) = q
        && let Some(&a) = one_step.iter().max_by(|&&a, &&b| q[a].total_cmp(&q[b]))
    {
        return a;
    }
    let e = &env.scenario().spec().ego;
    let creep = env.ego().s < e.creep_limit_s - 0.05;
    let wanted = if creep {
        Control::Creep
    } else {
        Control::Wait(1)
    };
    one_step
        .iter()
        .copied()
        .find(|&a| set.decode(a).ok() == Some(wanted))
        .or_else(|| one_step.first().copied())
        .unwrap_or(go)
}

impl Policy for ShieldedPolicy {
    fn name(&self) -> String {
        format!("{}+shield", self.inner.name())
    }

    fn supports(&self, set: ActionSet) -> Result<(), SimError> {
        self.inner.supports(set)?;
        set.final_go_for(&self.name(), "the shield checks a final go")
            .map(|_| ())
    }

    fn act(
        &self,
        envs: &[Env],
        rngs: &mut [PolicyRng],
        actions: &mut [usize],
    ) -> Result<(), SimError> {
        self.inner.act(envs, rngs, actions)?;
        let mut cars = Vec::new();
        for (env, a) in envs.iter().zip(actions.iter_mut()) {
            let Some(go) = env.config().action_set.absorbing_go() else {
                continue;
            };
            if *a != go || env.ego().committed {
                continue;
            }
            self.counters.go_decisions.fetch_add(1, Ordering::Relaxed);
            if let Some(threat) = self.check(env, &mut cars) {
                self.counters.vetoes.fetch_add(1, Ordering::Relaxed);
                if threat.car.phantom {
                    self.counters.phantom_vetoes.fetch_add(1, Ordering::Relaxed);
                }
                let kind = match threat.kind {
                    ThreatKind::Crossing => 0,
                    ThreatKind::Ahead => 1,
                    ThreatKind::Behind => 2,
                };
                self.counters.by_kind[kind].fetch_add(1, Ordering::Relaxed);
                *a = self.fallback(env, go)?;
            }
        }
        Ok(())
    }

    fn values(&self, env: &Env) -> Result<Option<Vec<f32>>, SimError> {
        self.inner.values(env)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::EnvConfig;
    use crate::policy::TtcPolicy;
    use crate::scenario::Scenario;
    use rand::SeedableRng;

    #[test]
    fn a_vetoed_go_becomes_a_one_step_wait_and_is_counted() {
        let sc = Arc::new(Scenario::builtin("left").unwrap());
        let mut env = Env::new(Arc::clone(&sc), EnvConfig::for_actions(ActionSet::Ttg));
        env.clear_traffic();
        env.set_ego(sc.spec().ego.stop_line_s, 0.0, false);
        let z = sc.lanes()[0].zone.unwrap();
        env.place_car(0, z.lane_in - 12.0, 15.0).unwrap();
        // TTC with a zero threshold goes whenever no car is in the zone.
        let policy = ShieldedPolicy::new(
            Box::new(TtcPolicy::new(0.0, false)),
            ShieldParams::default(),
        );
        let mut rng = [PolicyRng::seed_from_u64(0)];
        let mut action = [usize::MAX];
        policy
            .act(std::slice::from_ref(&env), &mut rng, &mut action)
            .unwrap();
        assert_eq!(ActionSet::Ttg.decode(action[0]).unwrap(), Control::Wait(1));
        let stats = policy.counters().stats();
        assert_eq!(
            (stats.go_decisions, stats.vetoes, stats.crossing),
            (1, 1, 1)
        );

        // On an empty road the go passes.
        env.clear_traffic();
        policy
            .act(std::slice::from_ref(&env), &mut rng, &mut action)
            .unwrap();
        assert_eq!(ActionSet::Ttg.decode(action[0]).unwrap(), Control::Go);
        let stats = policy.counters().stats();
        assert_eq!((stats.go_decisions, stats.vetoes), (2, 1));
        assert_eq!(policy.name(), "ttc:0+shield");
        assert!(policy.supports(ActionSet::Sequential).is_err());
    }
}
