//! Policies that drive environments: the [`Policy`] trait, the baselines
//! (TTC, TTC with creep, random) and parsing of policy strings.
//!
//! A [`Policy`] decides for a batch of environments in one call, so a
//! network acts on all of them with one forward pass. Besides the
//! baselines: [`NeverPolicy`] (waits until the time limit),
//! [`ShieldedPolicy`] (any policy behind the safety shield) and
//! [`OraclePolicy`] (sees hidden cars and tries each *go* first: the upper
//! bound under occlusion).

mod never;
mod oracle;
mod random;
mod shielded;
mod ttc;

pub use never::{GoPolicy, NeverPolicy};
pub use oracle::OraclePolicy;
pub use random::RandomPolicy;
pub use shielded::{ShieldCounters, ShieldStats, ShieldedPolicy, shield_fallback};
pub use ttc::TtcPolicy;

use rand_xoshiro::Xoshiro256PlusPlus;

use crate::action::{ActionSet, Intent};
use crate::env::Env;
use crate::error::SimError;

/// Random number generator handed to a policy, one per environment, so a
/// stochastic policy's choices depend only on its episode's seed.
pub type PolicyRng = Xoshiro256PlusPlus;

/// The rules' `act`: for each environment, the action of its action set
/// that carries out `intent(env)` at the ego's speed
/// ([`ActionSet::encode`]); an error naming `policy` where the set cannot
/// (TTG has no creep).
fn act_by_intent(
    policy: &dyn Policy,
    envs: &[Env],
    actions: &mut [usize],
    intent: impl Fn(&Env) -> Intent,
) -> Result<(), SimError> {
    for (env, a) in envs.iter().zip(actions.iter_mut()) {
        let set = env.config().action_set;
        let p = &env.scenario().spec().ego.params;
        *a = set
            .encode(intent(env), env.ego().v, p.creep_speed)
            .ok_or_else(|| SimError::Unsupported {
                policy: policy.name(),
                set: set.name(),
            })?;
    }
    Ok(())
}

/// Chooses actions for a batch of environments in one call, so a neural
/// policy can run one batched forward pass for all of them.
///
/// Cost: the baselines are O(cars) per environment; a neural policy is one
/// forward pass per call. Thread safety: `Send + Sync`; [`crate::evaluate`]
/// calls `act` from several threads at once on disjoint batches.
pub trait Policy: Send + Sync + std::fmt::Debug {
    /// Name for reports, e.g. `ttc:6.5`.
    fn name(&self) -> String;

    /// Whether this policy can drive `set`; an error says why not.
    fn supports(&self, set: ActionSet) -> Result<(), SimError>;

    /// Writes one action index per environment into `actions`. The three
    /// slices have equal lengths; every environment is running (not done).
    fn act(
        &self,
        envs: &[Env],
        rngs: &mut [PolicyRng],
        actions: &mut [usize],
    ) -> Result<(), SimError>;

    /// The policy's value of each action in `env`'s present state, when it
    /// has values (a Q-network); `None` for rules. A diagnostic
    /// ([`crate::go_risk`] reads it at its probes), not used to act.
    fn values(&self, _env: &Env) -> Result<Option<Vec<f32>>, SimError> {
        Ok(None)
    }
}

/// A baseline policy as parsed from its string form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PolicySpec {
    /// `ttc:<seconds>`: go when every visible car's time to collision
    /// exceeds the threshold.
    Ttc(f64),
    /// `ttc-creep:<seconds>`: creep until the conflicting lanes are in
    /// view, then the TTC rule.
    TtcCreep(f64),
    /// `random`: uniform over the action set.
    Random,
    /// Never goes ([`NeverPolicy`]).
    Never,
    /// `go`: wants to go at every decision ([`GoPolicy`]).
    Go,
    /// `oracle:<futures>`: goes when going reaches the goal in every one of
    /// that many forks of the present, hidden cars included
    /// ([`OraclePolicy`]).
    Oracle(u32),
}

impl PolicySpec {
    /// The policy.
    pub fn build(self) -> Box<dyn Policy> {
        match self {
            Self::Ttc(t) => Box::new(TtcPolicy::new(t, false)),
            Self::TtcCreep(t) => Box::new(TtcPolicy::new(t, true)),
            Self::Random => Box::new(RandomPolicy),
            Self::Never => Box::new(NeverPolicy),
            Self::Go => Box::new(GoPolicy),
            Self::Oracle(k) => Box::new(OraclePolicy::new(k)),
        }
    }
}

impl std::str::FromStr for PolicySpec {
    type Err = SimError;

    fn from_str(s: &str) -> Result<Self, SimError> {
        let err = |problem: &str| SimError::PolicySpec {
            spec: s.to_owned(),
            problem: problem.to_owned(),
        };
        match s {
            "random" => return Ok(Self::Random),
            "never" => return Ok(Self::Never),
            "go" => return Ok(Self::Go),
            _ => {}
        }
        let (kind, value) = s.split_once(':').ok_or_else(|| {
            err("expected ttc:<seconds>, ttc-creep:<seconds>, oracle:<futures>, random, never or go")
        })?;
        if kind == "oracle" {
            return match value.parse::<u32>() {
                Ok(k) if k > 0 => Ok(Self::Oracle(k)),
                _ => Err(err(
                    "the oracle's futures must be a whole number, 1 or more",
                )),
            };
        }
        let t: f64 = value
            .parse()
            .map_err(|_| err("the threshold must be a number of seconds"))?;
        if !(t.is_finite() && t >= 0.0) {
            return Err(err(
                "the threshold must be a finite number of seconds, zero or more",
            ));
        }
        match kind {
            "ttc" => Ok(Self::Ttc(t)),
            "ttc-creep" => Ok(Self::TtcCreep(t)),
            _ => Err(err(
                "expected ttc:<seconds>, ttc-creep:<seconds>, oracle:<futures>, random, never or go",
            )),
        }
    }
}

impl std::fmt::Display for PolicySpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Ttc(t) => write!(f, "ttc:{t}"),
            Self::TtcCreep(t) => write!(f, "ttc-creep:{t}"),
            Self::Random => f.write_str("random"),
            Self::Never => f.write_str("never"),
            Self::Go => f.write_str("go"),
            Self::Oracle(k) => write!(f, "oracle:{k}"),
        }
    }
}

/// Parses `ttc:<seconds>`, `ttc-creep:<seconds>`, `oracle:<futures>`,
/// `random`, `never` or `go` into a policy.
pub fn parse_policy(s: &str) -> Result<Box<dyn Policy>, SimError> {
    Ok(s.parse::<PolicySpec>()?.build())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_policy_strings() {
        assert_eq!(
            "ttc:6.5".parse::<PolicySpec>().unwrap(),
            PolicySpec::Ttc(6.5)
        );
        assert_eq!(
            "ttc-creep:3".parse::<PolicySpec>().unwrap(),
            PolicySpec::TtcCreep(3.0)
        );
        assert_eq!("random".parse::<PolicySpec>().unwrap(), PolicySpec::Random);
        assert_eq!("never".parse::<PolicySpec>().unwrap(), PolicySpec::Never);
        assert_eq!("go".parse::<PolicySpec>().unwrap(), PolicySpec::Go);
        assert_eq!(PolicySpec::Go.to_string(), "go");
        assert_eq!(
            "oracle:16".parse::<PolicySpec>().unwrap(),
            PolicySpec::Oracle(16)
        );
        assert_eq!(PolicySpec::Oracle(8).to_string(), "oracle:8");
        for bad in [
            "ttc",
            "ttc:",
            "ttc:x",
            "ttc:-1",
            "ttc:inf",
            "dqn:3",
            "",
            "oracle:0",
            "oracle:1.5",
        ] {
            assert!(bad.parse::<PolicySpec>().is_err(), "{bad}");
        }
        assert_eq!(parse_policy("ttc:2").unwrap().name(), "ttc:2");
        assert_eq!(PolicySpec::TtcCreep(1.5).to_string(), "ttc-creep:1.5");
    }
}
