//! Cell-by-cell comparison of our reports against SUMO's: the difference
//! of each metric with its interval (Newcombe's hybrid score interval for
//! rates, a normal interval for means), at 95 % for the report and 99 % for
//! the gate.

use std::collections::BTreeMap;

use crossroads_sim::{EvalReport, PolicySpec};
use serde::Serialize;

use super::{Pair, Plan};

const Z95: f64 = 1.959_963_984_540_054;
const Z99: f64 = 2.575_829_303_548_901;

/// What a cell's difference says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// The 95 % interval of the difference holds 0.
    Agrees,
    /// Only the 99 % interval holds 0.
    Differs,
    /// Not even the 99 % interval holds 0.
    Drifts,
}

/// One metric of one policy on one scenario, in both simulators.
#[derive(Debug, Clone, Serialize)]
pub struct SumoCell {
    /// Scenario.
    pub scenario: String,
    /// Policy.
    pub policy: String,
    /// Metric: success, collision, timeout (rates as fractions),
    /// time_s (mean time of successes), wait_s (mean wait before go),
    /// brake_light_s (traffic's brake light per trial).
    pub metric: &'static str,
    /// Our value.
    pub ours: Option<f64>,
    /// SUMO's value.
    pub sumo: Option<f64>,
    /// Ours minus SUMO's.
    pub diff: Option<f64>,
    /// 95 % interval of the difference.
    pub diff_ci95: Option<[f64; 2]>,
    /// 99 % interval of the difference.
    pub diff_ci99: Option<[f64; 2]>,
    /// The verdict.
    pub verdict: Verdict,
    /// Whether `--strict` fails on a drift of this cell: success, collision
    /// and time of the TTC policies, the regime the tables stand on.
    pub gated: bool,
}

impl SumoCell {
    /// One line for a terminal.
    pub fn describe(&self) -> String {
        let pct = matches!(self.metric, "success" | "collision" | "timeout");
        let f = |v: Option<f64>| match v {
            Some(v) if pct => format!("{:.2} %", 100.0 * v),
            Some(v) => format!("{v:.2} s"),
            None => "-".to_owned(),
        };
        let ci = self.diff_ci99.map_or("-".to_owned(), |[lo, hi]| {
            if pct {
                format!("[{:+.2}, {:+.2}] points", 100.0 * lo, 100.0 * hi)
            } else {
                format!("[{lo:+.2}, {hi:+.2}] s")
            }
        });
        format!(
            "{} {} {}: ours {} vs SUMO {} (difference 99 % interval {ci})",
            self.scenario,
            self.policy,
            self.metric,
            f(self.ours),
            f(self.sumo)
        )
    }
}

/// Largest difference of the empty-road drive time that agrees, s: the
/// drive is deterministic in both simulators, so no interval applies.
pub const EMPTY_TOLERANCE_S: f64 = 0.3;

/// Every cell of every pair; TTC cells gated where their plan is.
pub fn cells(pairs: &BTreeMap<String, Vec<Pair>>, plans: &[Plan]) -> Vec<SumoCell> {
    let mut out = Vec::new();
    for (scenario, list) in pairs {
        let plan_gated = plans
            .iter()
            .find(|p| &p.scenario == scenario)
            .is_none_or(|p| p.gated);
        if scenario.ends_with("-empty") {
            for pair in list {
                let (o, s) = (pair.ours.mean_time_s, pair.sumo.mean_time_s);
                let diff = o.zip(s).map(|(o, s)| o - s);
                let verdict = match diff {
                    Some(d) if d.abs() <= EMPTY_TOLERANCE_S => Verdict::Agrees,
                    _ => Verdict::Drifts,
                };
                out.push(SumoCell {
                    scenario: scenario.clone(),
                    policy: pair.policy.to_string(),
                    metric: "time_s",
                    ours: o,
                    sumo: s,
                    diff,
                    diff_ci95: None,
                    diff_ci99: None,
                    verdict,
                    gated: true,
                });
            }
            continue;
        }
        for pair in list {
            let gated =
                plan_gated && matches!(pair.policy, PolicySpec::Ttc(_) | PolicySpec::TtcCreep(_));
            let (o, s) = (&pair.ours, &pair.sumo);
            let mut push = |metric, diff: Option<Diff>, ours, sumo, gate| {
                out.push(cell(
                    scenario,
                    pair,
                    metric,
                    diff,
                    ours,
                    sumo,
                    gated && gate,
                ));
            };
            let rates: [(&'static str, RateOf); 3] = [
                ("success", |r| r.success_rate),
                ("collision", |r| r.collision_rate),
                ("timeout", |r| r.timeout_rate),
            ];
            for (metric, rate) in rates {
                let (po, ps) = (rate(o), rate(s));
                let d = rate_diff(po, o.trials, ps, s.trials);
                push(metric, Some(d), Some(po), Some(ps), metric != "timeout");
            }
            let times = |r: &EvalReport| r.mean_time_s.zip(r.mean_time_ci);
            push(
                "time_s",
                mean_diff(times(o), times(s)),
                o.mean_time_s,
                s.mean_time_s,
                true,
            );
            let waits = |r: &EvalReport| r.mean_wait_s.zip(r.mean_wait_ci);
            push(
                "wait_s",
                mean_diff(waits(o), waits(s)),
                o.mean_wait_s,
                s.mean_wait_s,
                false,
            );
            let lights = |r: &EvalReport| Some((r.mean_brake_light_s, r.mean_brake_light_ci));
            push(
                "brake_light_s",
                mean_diff(lights(o), lights(s)),
                Some(o.mean_brake_light_s),
                Some(s.mean_brake_light_s),
                false,
            );
        }
    }
    out
}

/// Reads one rate of a report.
type RateOf = fn(&EvalReport) -> f64;

/// A difference with its 95 % and 99 % intervals.
#[derive(Debug, Clone, Copy)]
struct Diff {
    value: f64,
    ci95: [f64; 2],
    ci99: [f64; 2],
}

fn cell(
    scenario: &str,
    pair: &Pair,
    metric: &'static str,
    diff: Option<Diff>,
    ours: Option<f64>,
    sumo: Option<f64>,
    gated: bool,
) -> SumoCell {
    let holds = |[lo, hi]: [f64; 2]| lo <= 1e-12 && hi >= -1e-12;
    let verdict = match diff {
        None => Verdict::Agrees,
        Some(d) if holds(d.ci95) => Verdict::Agrees,
        Some(d) if holds(d.ci99) => Verdict::Differs,
        Some(_) => Verdict::Drifts,
    };
    SumoCell {
        scenario: scenario.to_owned(),
        policy: pair.policy.to_string(),
        metric,
        ours,
        sumo,
        diff: diff.map(|d| d.value),
        diff_ci95: diff.map(|d| d.ci95),
        diff_ci99: diff.map(|d| d.ci99),
        verdict,
        gated,
    }
}

/// Wilson score interval of a rate `p` over `n` trials at `z`.
fn wilson(p: f64, n: u64, z: f64) -> [f64; 2] {
    if n == 0 {
        return [0.0, 1.0];
    }
    let n = n as f64;
    let z2 = z * z;
    let denom = 1.0 + z2 / n;
    let center = (p + z2 / (2.0 * n)) / denom;
    let half = z * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt() / denom;
    [(center - half).max(0.0), (center + half).min(1.0)]
}

/// Newcombe's hybrid score interval (method 10) for `p1 - p2`.
fn rate_diff(p1: f64, n1: u64, p2: f64, n2: u64) -> Diff {
    let at = |z| {
        let [l1, u1] = wilson(p1, n1, z);
        let [l2, u2] = wilson(p2, n2, z);
        let d = p1 - p2;
        [
            d - ((p1 - l1).powi(2) + (u2 - p2).powi(2)).sqrt(),
            d + ((u1 - p1).powi(2) + (p2 - l2).powi(2)).sqrt(),
        ]
    };
    Diff {
        value: p1 - p2,
        ci95: at(Z95),
        ci99: at(Z99),
    }
}

/// Difference of two means given with their 95 % normal intervals.
fn mean_diff(
    a: Option<(f64, crossroads_sim::Interval)>,
    b: Option<(f64, crossroads_sim::Interval)>,
) -> Option<Diff> {
    let ((ma, ia), (mb, ib)) = (a?, b?);
    let se = |i: crossroads_sim::Interval| (i.high - i.low) / (2.0 * Z95);
    let se = se(ia).hypot(se(ib));
    let d = ma - mb;
    Some(Diff {
        value: d,
        ci95: [d - Z95 * se, d + Z95 * se],
        ci99: [d - Z99 * se, d + Z99 * se],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn newcombe_interval_matches_the_textbook_example() {
        // Newcombe (1998), table II, example (a): 56/70 vs 48/80, method 10
        // gives 0.0524 to 0.3339.
        let d = rate_diff(56.0 / 70.0, 70, 48.0 / 80.0, 80);
        assert!((d.ci95[0] - 0.0524).abs() < 5e-4, "{:?}", d.ci95);
        assert!((d.ci95[1] - 0.3339).abs() < 5e-4, "{:?}", d.ci95);
        assert!(d.ci99[0] < d.ci95[0] && d.ci99[1] > d.ci95[1]);
    }

    #[test]
    fn equal_rates_agree_and_far_ones_drift() {
        let same = rate_diff(0.5, 300, 0.5, 300);
        assert!(same.ci95[0] < 0.0 && same.ci95[1] > 0.0);
        let far = rate_diff(0.9, 300, 0.5, 300);
        assert!(far.ci99[0] > 0.0);
    }
}
