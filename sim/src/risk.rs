//! How risky a policy's *go* decisions were: every *go* of an evaluation is
//! replayed in `futures` forks of its environment ([`Env::fork`]: the same
//! present, other random traffic from there on), which estimates the
//! probability that going from that state collides. It tells a policy that
//! takes calculated risks (collisions after states where going usually
//! works) from one that makes mistakes (collisions the state already
//! decided), which call for different cures: the reward's trade-off, or
//! the network.
//!
//! With [`RiskOptions::missed`] it also probes the other side: every second
//! of waiting (or creeping), *go* is tried in the same forks, and a probe
//! where every fork reached the goal is a chance the policy passed up. It
//! tells a policy that times out because no gap came from one that let
//! gaps go by (too conservative a Q(go), or too optimistic a Q(wait)).
//! For a policy with values ([`Policy::values`]) the probes also read its
//! Q-values, so [`ValueMargins`] says which of the two it is, and whether
//! the network told safe moments from doomed ones at all.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use serde::Serialize;

use crate::action::Control;
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

/// Simulation steps between two probes of a trial's waiting decisions
/// (5: once a second at 0.2 s steps).
pub const PROBE_EVERY_STEPS: u32 = 5;

/// How [`go_risk`] replays decisions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RiskOptions {
    /// Forks per decision. At least 1.
    pub futures: u32,
    /// Whether to probe waiting decisions too (every
    /// [`PROBE_EVERY_STEPS`]): would going there have reached the goal?
    pub missed: bool,
}

/// Seconds of a car at the speed limit that a probe's view must cover
/// upstream on every conflicting lane to count as *in view*: about the
/// ego's time to clear the junction from the creep limit. A safe chance out
/// of view was luck the policy could not see; the value margins are read
/// at probes in view only.
pub const IN_VIEW_S: f64 = 5.0;

/// A waiting decision at which going reached the goal in every fork.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SafeChance {
    /// Trial index.
    pub trial: u64,
    /// Simulation step of the decision.
    pub step: u32,
    /// Whether the conflicting lanes were in view ([`IN_VIEW_S`]).
    pub in_view: bool,
}

/// What the probes of waiting decisions found ([`RiskOptions::missed`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MissedReport {
    /// Seconds between two probes of a trial at least.
    pub probe_every_s: f64,
    /// Waiting decisions probed.
    pub probes: u64,
    /// Of those, probes where going reached the goal in every fork.
    pub safe: u64,
    /// Of those, probes with the conflicting lanes in view, [`IN_VIEW_S`]
    /// at the speed limit upstream (metres in `in_view_m`).
    pub safe_in_view: u64,
    /// The view a probe needs to count as in view, metres.
    pub in_view_m: f64,
    /// Trials that timed out.
    pub timeouts: u64,
    /// Of those, trials that passed up at least one safe chance.
    pub timeouts_with_chance: u64,
    /// Of those, trials that passed up a safe chance in view.
    pub timeouts_with_chance_in_view: u64,
    /// Trials that went and had a safe chance before they did.
    pub went_late: u64,
    /// Median seconds from a trial's first safe chance to its *go*, over
    /// `went_late` (`None` when there are none).
    pub median_delay_s: Option<f64>,
    /// The first safe chance of timed-out trials, earliest trials first, at
    /// most [`RISKIEST_SHOWN`].
    pub passed_up: Vec<SafeChance>,
    /// The policy's values at the probes, when it has values.
    pub values: Option<ValueMargins>,
}

/// What a Q-network thought at the probed waits in view ([`IN_VIEW_S`]):
/// at the safe ones (going reached the goal in every future) and at the
/// doomed ones (going collided in more than half of them). A network that tells them apart but waits
/// at safe moments has too high a Q(wait) or too low a Q(go) everywhere; one
/// whose margins are alike on both has not learnt to read the state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ValueMargins {
    /// At safe probes.
    pub safe: ValueStats,
    /// At doomed probes.
    pub doomed: ValueStats,
}

/// Medians of a network's values over a class of probes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ValueStats {
    /// Probes in the class.
    pub probes: u64,
    /// Median Q(s, go) (`None` without probes).
    pub q_go: Option<f64>,
    /// Median of the best other action's value.
    pub q_other: Option<f64>,
    /// Median of Q(go) minus the best other (negative: the network waited).
    pub margin: Option<f64>,
    /// Share of the probes where the margin was above -0.05 (nearly
    /// indifferent or going).
    pub near: Option<f64>,
}

/// Margins closer than this to 0 count as nearly indifferent.
const NEAR_MARGIN: f64 = 0.05;

impl ValueStats {
    /// The medians of `(q_go, q_other)` pairs.
    fn of(mut pairs: Vec<(f64, f64)>) -> Self {
        let median = |mut v: Vec<f64>| -> Option<f64> {
            v.sort_by(f64::total_cmp);
            (!v.is_empty()).then(|| v[v.len() / 2])
        };
        let n = pairs.len();
        let margins: Vec<f64> = pairs.iter().map(|(g, o)| g - o).collect();
        let near = (n > 0)
            .then(|| margins.iter().filter(|&&m| m > -NEAR_MARGIN).count() as f64 / n as f64);
        let others = pairs.iter().map(|p| p.1).collect();
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        Self {
            probes: n as u64,
            q_go: (n > 0).then(|| pairs[n / 2].0),
            q_other: median(others),
            margin: median(margins),
            near,
        }
    }
}

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
    /// Chances passed up, when waiting decisions were probed.
    pub missed: Option<MissedReport>,
}

/// Evaluates `policy` like [`crate::evaluate`] and replays each of its *go*
/// decisions in `options.futures` forks (and, with `options.missed`, tries
/// *go* from its waiting decisions). The action set must have a *go* (TTG
/// or Creep-and-Go). The report is the same whatever the number of
/// threads.
pub fn go_risk(
    scenario: &Arc<Scenario>,
    policy: &dyn Policy,
    config: &EvalConfig,
    options: RiskOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<RiskReport, SimError> {
    let futures = options.futures;
    if futures == 0 {
        return Err(SimError::EvalConfig(
            "risk needs at least 1 future per decision".to_owned(),
        ));
    }
    let go = config.action_set.absorbing_go().ok_or_else(|| {
        SimError::EvalConfig(format!(
            "risk replays go decisions; the {} action set has none (use ttg or creep)",
            config.action_set.name()
        ))
    })?;
    let found = Mutex::new(Vec::new());
    let in_view_m = IN_VIEW_S * scenario.spec().speed_limit;
    let probes = Mutex::new(Probes {
        in_view_m,
        ..Probes::default()
    });
    let watch = |trial: u64, env: &Env, action: usize| -> Result<(), SimError> {
        let base = !episode_seed(config.seed, trial);
        // Outcomes of going now in each fork: (collided, succeeded).
        let forks = || -> Result<(u32, u32), SimError> {
            let (mut collided, mut succeeded) = (0u32, 0u32);
            for j in 0..futures {
                let mut fork = env.fork(episode_seed(base, u64::from(j)));
                fork.step(go)?;
                match fork.metrics().outcome {
                    Some(Outcome::Collision) => collided += 1,
                    Some(Outcome::Success) => succeeded += 1,
                    _ => {}
                }
            }
            Ok((collided, succeeded))
        };
        if config.action_set.decode(action)? != Control::Go {
            if options.missed {
                let step = env.steps();
                let due = probes
                    .lock()
                    .map_err(|_| SimError::EvalConfig("a risk worker panicked".to_owned()))?
                    .due(trial, step);
                if due {
                    let (collided, succeeded) = forks()?;
                    let in_view = env.sees_conflicts(in_view_m);
                    let values = if in_view {
                        policy.values(env)?.map(|q| go_and_best_other(&q, go))
                    } else {
                        None
                    };
                    let class = if succeeded == futures {
                        Some(true)
                    } else if 2 * collided > futures {
                        Some(false)
                    } else {
                        None
                    };
                    probes
                        .lock()
                        .map_err(|_| SimError::EvalConfig("a risk worker panicked".to_owned()))?
                        .record(
                            SafeChance {
                                trial,
                                step,
                                in_view,
                            },
                            class,
                            values,
                        );
                }
            }
            return Ok(());
        }
        let (collided, _) = forks()?;
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
    let missed = options.missed.then(|| {
        probes
            .into_inner()
            .unwrap_or_default()
            .report(&results, &decisions, scenario.dt())
    });
    let mut r = report(eval, futures, decisions, collisions);
    r.missed = missed;
    Ok(r)
}

/// Q(go) and the best other action's value in `q`.
fn go_and_best_other(q: &[f32], go: usize) -> (f64, f64) {
    let other = q
        .iter()
        .enumerate()
        .filter(|&(a, _)| a != go)
        .map(|(_, &v)| f64::from(v))
        .fold(f64::NEG_INFINITY, f64::max);
    (f64::from(q[go]), other)
}

/// The probes of waiting decisions, gathered across worker threads.
#[derive(Debug, Default)]
struct Probes {
    /// Per trial, the step of its last probe.
    last: HashMap<u64, u32>,
    /// Probes made.
    count: u64,
    /// The safe ones.
    safe: Vec<SafeChance>,
    /// The view a probe needs to count as in view, metres.
    in_view_m: f64,
    /// The policy's (Q(go), best other) at safe and at doomed probes in
    /// view.
    safe_values: Vec<(f64, f64)>,
    doomed_values: Vec<(f64, f64)>,
    /// Whether the policy has values.
    has_values: bool,
}

impl Probes {
    /// Whether a waiting decision of `trial` at `step` is due a probe, a
    /// [`PROBE_EVERY_STEPS`] after the last (each trial runs on one thread
    /// in step order).
    fn due(&mut self, trial: u64, step: u32) -> bool {
        match self.last.get(&trial) {
            Some(&last) if step < last + PROBE_EVERY_STEPS => false,
            _ => {
                self.last.insert(trial, step);
                true
            }
        }
    }

    /// Records the probe at `at`: `class` is `Some(true)` when it was
    /// safe, `Some(false)` when doomed; `values` the policy's (Q(go), best
    /// other), read in view only.
    fn record(&mut self, at: SafeChance, class: Option<bool>, values: Option<(f64, f64)>) {
        self.count += 1;
        if class == Some(true) {
            self.safe.push(at);
        }
        if let Some(v) = values {
            self.has_values = true;
            match class {
                Some(true) => self.safe_values.push(v),
                Some(false) => self.doomed_values.push(v),
                None => {}
            }
        }
    }

    /// Which trials passed up chances: timed out after one, or went later.
    fn report(
        mut self,
        results: &[crate::eval::TrialResult],
        decisions: &[GoDecision],
        dt: f64,
    ) -> MissedReport {
        self.safe.sort_by_key(|c| (c.trial, c.step));
        let mut first: HashMap<u64, SafeChance> = HashMap::new();
        let mut first_in_view: HashMap<u64, SafeChance> = HashMap::new();
        for c in &self.safe {
            first.entry(c.trial).or_insert(*c);
            if c.in_view {
                first_in_view.entry(c.trial).or_insert(*c);
            }
        }
        let timeouts_with_chance_in_view = results
            .iter()
            .enumerate()
            .filter(|(i, r)| {
                r.outcome == Outcome::Timeout && first_in_view.contains_key(&(*i as u64))
            })
            .count() as u64;
        let timeouts = results
            .iter()
            .filter(|r| r.outcome == Outcome::Timeout)
            .count() as u64;
        let mut passed_up: Vec<SafeChance> = results
            .iter()
            .enumerate()
            .filter(|(_, r)| r.outcome == Outcome::Timeout)
            .filter_map(|(i, _)| first.get(&(i as u64)).copied())
            .collect();
        let timeouts_with_chance = passed_up.len() as u64;
        passed_up.truncate(RISKIEST_SHOWN);
        let mut delays: Vec<f64> = decisions
            .iter()
            .filter_map(|d| {
                first
                    .get(&d.trial)
                    .filter(|c| c.step < d.step)
                    .map(|c| f64::from(d.step - c.step) * dt)
            })
            .collect();
        delays.sort_by(f64::total_cmp);
        MissedReport {
            probe_every_s: f64::from(PROBE_EVERY_STEPS) * dt,
            probes: self.count,
            safe: self.safe.len() as u64,
            safe_in_view: self.safe.iter().filter(|c| c.in_view).count() as u64,
            in_view_m: self.in_view_m,
            timeouts,
            timeouts_with_chance,
            timeouts_with_chance_in_view,
            went_late: delays.len() as u64,
            median_delay_s: (!delays.is_empty()).then(|| delays[delays.len() / 2]),
            passed_up,
            values: self.has_values.then(|| ValueMargins {
                safe: ValueStats::of(self.safe_values),
                doomed: ValueStats::of(self.doomed_values),
            }),
        }
    }
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
        missed: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::action::ActionSet;
    use crate::env::EnvConfig;
    use crate::policy::parse_policy;

    fn opts(futures: u32) -> RiskOptions {
        RiskOptions {
            futures,
            missed: false,
        }
    }

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
        let r = go_risk(&left(), policy.as_ref(), &config, opts(8), &|_| {}).unwrap();
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
    fn probes_find_the_chances_a_policy_passes_up() {
        // Never going on Left (0.2 cars/s a lane) times out every trial,
        // though gaps come by; every timeout passed one up.
        let never = parse_policy("never").unwrap();
        let config = EvalConfig::new(ActionSet::Ttg, 50, 3);
        let options = RiskOptions {
            futures: 8,
            missed: true,
        };
        let r = go_risk(&left(), never.as_ref(), &config, options, &|_| {}).unwrap();
        let m = r.missed.expect("probed");
        assert_eq!((r.decisions, m.timeouts), (0, 50));
        // 20 s of waiting: one probe a second at most (waits of 8 steps
        // make some seconds share a probe).
        assert!(m.probes > 50 * 10 && m.probes <= 50 * 20, "{m:?}");
        assert!(m.timeouts_with_chance >= 45, "{m:?}");
        assert!(m.safe > 0 && m.safe < m.probes, "{m:?}");
        assert_eq!(m.went_late, 0);
        assert!(m.passed_up.windows(2).all(|w| w[0].trial < w[1].trial));

        // A cautious TTC rule (6 s, the HCM's gap) succeeds but lets safe
        // gaps go by first; without probes nothing is reported.
        let cautious = parse_policy("ttc:6").unwrap();
        let r = go_risk(&left(), cautious.as_ref(), &config, options, &|_| {}).unwrap();
        let m = r.missed.expect("probed");
        assert!(m.went_late > 0, "{m:?}");
        assert!(m.median_delay_s.is_some_and(|d| d > 0.0), "{m:?}");
        let plain = go_risk(&left(), cautious.as_ref(), &config, opts(8), &|_| {}).unwrap();
        assert_eq!(plain.missed, None);
        assert_eq!(plain.eval, r.eval, "probing does not change the trials");
    }

    /// Never goes, and says so with constant values: Q(go) 0.2 against
    /// 0.5 for every other action.
    #[derive(Debug)]
    struct ValuedNever;

    impl Policy for ValuedNever {
        fn name(&self) -> String {
            "valued-never".to_owned()
        }
        fn supports(&self, set: ActionSet) -> Result<(), SimError> {
            crate::NeverPolicy.supports(set)
        }
        fn act(
            &self,
            envs: &[Env],
            rngs: &mut [crate::PolicyRng],
            actions: &mut [usize],
        ) -> Result<(), SimError> {
            crate::NeverPolicy.act(envs, rngs, actions)
        }
        fn values(&self, env: &Env) -> Result<Option<Vec<f32>>, SimError> {
            let set = env.config().action_set;
            let go = set.absorbing_go().expect("a go");
            Ok(Some(
                (0..set.num_actions())
                    .map(|a| if a == go { 0.2 } else { 0.5 })
                    .collect(),
            ))
        }
    }

    #[test]
    fn probes_read_the_values_at_safe_and_doomed_waits() {
        let config = EvalConfig::new(ActionSet::Ttg, 30, 3);
        let options = RiskOptions {
            futures: 8,
            missed: true,
        };
        let r = go_risk(&left(), &ValuedNever, &config, options, &|_| {}).unwrap();
        let m = r.missed.expect("probed");
        let v = m.values.expect("the policy has values");
        // Left has no occluders: every probe is in view.
        assert_eq!(m.safe_in_view, m.safe);
        assert_eq!(m.timeouts_with_chance_in_view, m.timeouts_with_chance);
        assert_eq!(v.safe.probes, m.safe, "every safe probe read");
        assert!(v.doomed.probes > 0, "{v:?}");
        assert!(v.safe.probes + v.doomed.probes <= m.probes);
        for s in [v.safe, v.doomed] {
            assert_eq!(s.q_go, Some(0.2f32.into()));
            assert_eq!(s.q_other, Some(0.5f32.into()));
            let margin = s.margin.unwrap();
            assert!((margin + 0.3).abs() < 1e-6, "{margin}");
            assert_eq!(s.near, Some(0.0));
        }
        // A rule has no values.
        let never = parse_policy("never").unwrap();
        let r = go_risk(&left(), never.as_ref(), &config, options, &|_| {}).unwrap();
        assert_eq!(r.missed.expect("probed").values, None);
    }

    #[test]
    fn value_stats_are_medians_of_hand_made_pairs() {
        // Margins 1, -1 and -0.02: median -0.02, two of three above -0.05.
        let s = ValueStats::of(vec![(1.0, 0.0), (0.0, 1.0), (0.5, 0.52)]);
        assert_eq!(s.probes, 3);
        assert_eq!(s.q_go, Some(0.5));
        assert_eq!(s.q_other, Some(0.52));
        assert!((s.margin.unwrap() + 0.02).abs() < 1e-12);
        assert!((s.near.unwrap() - 2.0 / 3.0).abs() < 1e-12);
        let empty = ValueStats::of(Vec::new());
        assert_eq!(
            (empty.probes, empty.q_go, empty.margin, empty.near),
            (0, None, None, None)
        );
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
                .install(|| go_risk(&left(), policy.as_ref(), &config, opts(4), &|_| {}).unwrap())
        };
        assert_eq!(on(1), on(2));
    }

    #[test]
    fn risk_needs_a_go_and_a_future() {
        let policy = parse_policy("random").unwrap();
        let seq = EvalConfig::new(ActionSet::Sequential, 10, 0);
        let err = go_risk(&left(), policy.as_ref(), &seq, opts(4), &|_| {}).unwrap_err();
        assert!(err.to_string().contains("sequential"), "{err}");
        let ttg = EvalConfig::new(ActionSet::Ttg, 10, 0);
        let err = go_risk(&left(), policy.as_ref(), &ttg, opts(0), &|_| {}).unwrap_err();
        assert!(err.to_string().contains("at least 1 future"), "{err}");
    }
}
