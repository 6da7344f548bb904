//! How risky a policy's *go* decisions were: every *go* of an evaluation is
//! replayed in `futures` forks of its environment ([`Env::fork`]: the same
//! present, other random traffic from there on), which estimates the
//! probability that going from that state collides. It tells a policy that
//! takes calculated risks (collisions after states where going usually
//! works) from one that makes mistakes (collisions the state already
//! decided), which call for different cures: the reward's trade-off, or
//! the network.

use std::sync::{Arc, Mutex};

use serde::Serialize;

use crate::action::{ActionSet, Control};
use crate::env::{Env, Outcome};
use crate::error::SimError;
use crate::eval::{EvalConfig, EvalReport, run_trials_watched, summarize};
use crate::policy::Policy;
use crate::scenario::Scenario;
use crate::seed::episode_seed;

/// Upper ends of the probability bins; the first holds exactly 0.
const BIN_HIGHS: [f64; 5] = [0.0, 0.1, 0.5, 0.9, 1.0];

/// How many decisions [`RiskReport::riskiest`] lists at most.
pub const RISKIEST_SHOWN: usize = 20;

/// One *go* decision and what its forks did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GoDecision {
    /// Trial index (`crossroads render --seed S --trial I` draws it).
    pub trial: u64,
    /// Simulation step at which the policy went.
    pub step: u32,
    /// Fraction of the forks that collided.
    pub p_collision: f64,
    /// Whether the trial itself collided.
    pub collided: bool,
}

/// Decisions whose estimated collision probability lies in `(low, high]`
/// (exactly 0 for the first bin).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RiskBin {
    /// Lower end (exclusive, except for the bin of 0).
    pub low: f64,
    /// Upper end (inclusive).
    pub high: f64,
    /// *Go* decisions in the bin.
    pub decisions: u64,
    /// Of those, trials that collided.
    pub collisions: u64,
}

/// What [`go_risk`] measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RiskReport {
    /// The evaluation itself (the same as [`crate::evaluate`]'s).
    pub eval: EvalReport,
    /// Forks per decision.
    pub futures: u32,
    /// *Go* decisions (at most one per trial: *go* is final).
    pub decisions: u64,
    /// Decisions by estimated collision probability.
    pub bins: Vec<RiskBin>,
    /// Collisions whose *go* had a collision probability above one half:
    /// the state made them likely, so a better policy would not have gone.
    pub foreseeable: u64,
    /// Collisions of trials that did not collide after a *go* (while
    /// creeping, say).
    pub other_collisions: u64,
    /// The collided decisions and then the riskiest others, highest
    /// probability first, at most [`RISKIEST_SHOWN`].
    pub riskiest: Vec<GoDecision>,
}

/// Evaluates `policy` like [`crate::evaluate`] and replays each of its *go*
/// decisions in `futures` forks. The action set must have a *go* (TTG or
/// Creep-and-Go). The report is the same whatever the number of threads.
pub fn go_risk(
    scenario: &Arc<Scenario>,
    policy: &dyn Policy,
    config: &EvalConfig,
    futures: u32,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<RiskReport, SimError> {
    if futures == 0 {
        return Err(SimError::EvalConfig(
            "risk needs at least 1 future per decision".to_owned(),
        ));
    }
    if config.action_set == ActionSet::Sequential {
        return Err(SimError::EvalConfig(format!(
            "risk replays go decisions; the {} action set has none (use ttg or creep)",
            config.action_set.name()
        )));
    }
    let found = Mutex::new(Vec::new());
    let watch = |trial: u64, env: &Env, action: usize| -> Result<(), SimError> {
        if config.action_set.decode(action)? != Control::Go {
            return Ok(());
        }
        let base = !episode_seed(config.seed, trial);
        let mut collided = 0u32;
        for j in 0..futures {
            let mut fork = env.fork(episode_seed(base, u64::from(j)));
            fork.step(action)?;
            if fork.metrics().outcome == Some(Outcome::Collision) {
                collided += 1;
            }
        }
        let decision = GoDecision {
            trial,
            step: env.steps(),
            p_collision: f64::from(collided) / f64::from(futures),
            collided: false,
        };
        found
            .lock()
            .map_err(|_| SimError::EvalConfig("a risk worker panicked".to_owned()))?
            .push(decision);
        Ok(())
    };
    let results = run_trials_watched(scenario, policy, config, progress, &watch)?;
    let mut decisions = found
        .into_inner()
        .map_err(|_| SimError::EvalConfig("a risk worker panicked".to_owned()))?;
    for d in &mut decisions {
        d.collided = results[(d.trial) as usize].outcome == Outcome::Collision;
    }
    let collisions = results
        .iter()
        .filter(|r| r.outcome == Outcome::Collision)
        .count() as u64;
    let eval = summarize(scenario.name(), &policy.name(), config, &results);
    Ok(report(eval, futures, decisions, collisions))
}

/// Bins `decisions` and picks the riskiest; `collisions` counts every
/// collided trial (after a *go* or not).
fn report(
    eval: EvalReport,
    futures: u32,
    mut decisions: Vec<GoDecision>,
    collisions: u64,
) -> RiskReport {
    let mut bins: Vec<RiskBin> = BIN_HIGHS
        .iter()
        .scan(0.0, |low, &high| {
            let bin = RiskBin {
                low: *low,
                high,
                decisions: 0,
                collisions: 0,
            };
            *low = high;
            Some(bin)
        })
        .collect();
    for d in &decisions {
        let i = BIN_HIGHS
            .iter()
            .position(|&h| d.p_collision <= h)
            .unwrap_or(BIN_HIGHS.len() - 1);
        bins[i].decisions += 1;
        bins[i].collisions += u64::from(d.collided);
    }
    let collided_after_go = decisions.iter().filter(|d| d.collided).count() as u64;
    let foreseeable = decisions
        .iter()
        .filter(|d| d.collided && d.p_collision > 0.5)
        .count() as u64;
    // Collided first, then by probability, then by trial: a fixed order.
    decisions.sort_by(|a, b| {
        b.collided
            .cmp(&a.collided)
            .then(b.p_collision.total_cmp(&a.p_collision))
            .then(a.trial.cmp(&b.trial))
    });
    let count = decisions.len() as u64;
    decisions.retain(|d| d.collided || d.p_collision > 0.0);
    decisions.truncate(RISKIEST_SHOWN);
    RiskReport {
        eval,
        futures,
        decisions: count,
        bins,
        foreseeable,
        other_collisions: collisions - collided_after_go,
        riskiest: decisions,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::EnvConfig;
    use crate::policy::parse_policy;

    fn left() -> Arc<Scenario> {
        Arc::new(Scenario::builtin("left").unwrap())
    }

    #[test]
    fn a_fork_keeps_the_present_and_draws_its_own_future() {
        let mut env = Env::new(left(), EnvConfig::for_actions(ActionSet::Ttg));
        env.reset(3);
        for _ in 0..5 {
            env.step(1).unwrap();
        }
        let (mut a, mut b, mut c) = (env.fork(11), env.fork(11), env.fork(12));
        assert_eq!(a.steps(), env.steps());
        assert_eq!(a.ego(), env.ego());
        let mut differs = false;
        for _ in 0..40 {
            for e in [&mut a, &mut b, &mut c] {
                e.step(1).unwrap();
            }
            let speeds = |e: &Env| e.traffic().cars().map(|car| car.v).collect::<Vec<_>>();
            assert_eq!(speeds(&a), speeds(&b), "one seed, one future");
            differs |= speeds(&a) != speeds(&c);
        }
        assert!(differs, "another seed dawdles differently");
    }

    #[test]
    fn risk_accounts_for_every_go_and_every_collision() {
        // Going at random goes into gaps of every size.
        let policy = parse_policy("random").unwrap();
        let config = EvalConfig::new(ActionSet::Ttg, 400, 5);
        let r = go_risk(&left(), policy.as_ref(), &config, 8, &|_| {}).unwrap();
        let collisions = (r.eval.collision_rate * 400.0).round() as u64;
        assert!(collisions > 0, "{:?}", r.eval);
        assert_eq!(r.decisions, r.bins.iter().map(|b| b.decisions).sum::<u64>());
        assert!(r.decisions <= 400 && r.decisions > 300, "{}", r.decisions);
        let after_go: u64 = r.bins.iter().map(|b| b.collisions).sum();
        assert_eq!(after_go + r.other_collisions, collisions);
        assert!(r.foreseeable <= after_go);
        assert!(
            r.bins[0].decisions > 0 && r.bins[4].decisions > 0,
            "{:?}",
            r.bins
        );
        for d in &r.riskiest {
            let k = d.p_collision * 8.0;
            assert_eq!(k, k.round(), "{d:?}: a fraction of 8 forks");
        }
        // The evaluation is the plain one.
        let plain = crate::evaluate(&left(), policy.as_ref(), &config, &|_| {}).unwrap();
        assert_eq!(r.eval, plain);
    }

    #[test]
    fn risk_is_the_same_on_any_number_of_threads() {
        let policy = parse_policy("random").unwrap();
        let config = EvalConfig::new(ActionSet::Ttg, 200, 9);
        let on = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| go_risk(&left(), policy.as_ref(), &config, 4, &|_| {}).unwrap())
        };
        assert_eq!(on(1), on(2));
    }

    #[test]
    fn risk_needs_a_go_and_a_future() {
        let policy = parse_policy("random").unwrap();
        let seq = EvalConfig::new(ActionSet::Sequential, 10, 0);
        let err = go_risk(&left(), policy.as_ref(), &seq, 4, &|_| {}).unwrap_err();
        assert!(err.to_string().contains("sequential"), "{err}");
        let ttg = EvalConfig::new(ActionSet::Ttg, 10, 0);
        let err = go_risk(&left(), policy.as_ref(), &ttg, 0, &|_| {}).unwrap_err();
        assert!(err.to_string().contains("at least 1 future"), "{err}");
    }
}
