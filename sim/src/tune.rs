//! The TTC threshold sweep and the paper's tuning rule.

use std::sync::Arc;

use serde::Serialize;

use crate::action::ActionSet;
use crate::error::SimError;
use crate::eval::{EvalConfig, evaluate};
use crate::policy::TtcPolicy;
use crate::scenario::Scenario;

/// One threshold of a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SweepPoint {
    /// TTC threshold, s.
    pub threshold: f64,
    /// Fraction of trials that reached the goal.
    pub success_rate: f64,
    /// Fraction that collided.
    pub collision_rate: f64,
    /// Fraction that timed out.
    pub timeout_rate: f64,
    /// Mean time to goal of the successful trials, s.
    pub mean_time_s: Option<f64>,
    /// Mean braking time of traffic per trial, s.
    pub mean_brake_s: f64,
    /// Mean brake-light time of traffic per trial by SUMO's rule, s
    /// ([`crate::Traffic::brake_light_time_s`]).
    pub mean_brake_light_s: f64,
}

/// A sweep and the threshold the paper's rule picks.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TuneReport {
    /// Scenario name.
    pub scenario: String,
    /// Action set name.
    pub action_set: String,
    /// Whether the TTC rule creeps first.
    pub creep: bool,
    /// Trials per threshold.
    pub trials: u64,
    /// Base seed, the same for every threshold (common random numbers).
    pub seed: u64,
    /// The lowest threshold with zero collisions (the paper's rule), if any.
    pub best: Option<SweepPoint>,
    /// Every threshold, ascending.
    pub sweep: Vec<SweepPoint>,
}

/// Thresholds 0.0, 0.25, ..., 10.0 s.
pub fn default_thresholds() -> Vec<f64> {
    (0..=40).map(|i| f64::from(i) * 0.25).collect()
}

/// Evaluates the TTC rule at each threshold (sorted ascending) with the same
/// seeds and picks the lowest with zero collisions. `progress` counts
/// trials over the whole sweep (`thresholds.len() * trials`).
pub fn tune_ttc(
    scenario: &Arc<Scenario>,
    action_set: ActionSet,
    creep: bool,
    thresholds: &[f64],
    trials: u64,
    seed: u64,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<TuneReport, SimError> {
    let mut ts: Vec<f64> = thresholds.to_vec();
    if ts.iter().any(|t| !(t.is_finite() && *t >= 0.0)) {
        return Err(SimError::EvalConfig(
            "thresholds must be finite and non-negative".to_owned(),
        ));
    }
    ts.sort_by(f64::total_cmp);
    let config = EvalConfig::new(action_set, trials, seed);
    let mut sweep = Vec::with_capacity(ts.len());
    for t in ts {
        let r = evaluate(scenario, &TtcPolicy::new(t, creep), &config, progress)?;
        sweep.push(SweepPoint {
            threshold: t,
            success_rate: r.success_rate,
            collision_rate: r.collision_rate,
            timeout_rate: r.timeout_rate,
            mean_time_s: r.mean_time_s,
            mean_brake_s: r.mean_brake_s,
            mean_brake_light_s: r.mean_brake_light_s,
        });
    }
    let best = sweep.iter().find(|p| p.collision_rate == 0.0).copied();
    Ok(TuneReport {
        scenario: scenario.name().to_owned(),
        action_set: action_set.name().to_owned(),
        creep,
        trials,
        seed,
        best,
        sweep,
    })
}
