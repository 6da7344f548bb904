//! Prints TTC sweeps, the tuned TTC row of Table I and random-policy
//! results, for calibrating the simulator against the paper.
//!
//! `cargo run --release -p crossroads-sim --example calibrate -- [trials] [scenario...]`

use std::sync::Arc;

use crossroads_sim::{ActionSet, EvalConfig, RandomPolicy, Scenario, SimError, evaluate, tune_ttc};

fn main() -> Result<(), SimError> {
    let mut args = std::env::args().skip(1);
    let trials: u64 = args.next().and_then(|t| t.parse().ok()).unwrap_or(2000);
    let mut names: Vec<String> = args.collect();
    if names.is_empty() {
        names = ["right", "left", "left2", "forward", "challenge"]
            .map(String::from)
            .to_vec();
    }
    let thresholds: Vec<f64> = (0..=16).map(|i| f64::from(i) * 0.25).collect();
    for name in &names {
        let mut spec = Scenario::load(name)?.spec().clone();
        let env_f = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
        if let Some(v) = env_f("YIELD_DECEL") {
            spec.traffic.yield_decel = v;
        }
        if let Some(v) = env_f("REACTION") {
            spec.traffic.reaction_delay_s = v;
        }
        if let Some(v) = env_f("EGO_ACCEL") {
            spec.ego.params.accel = v;
        }
        if let Some(v) = env_f("LAT") {
            spec.ego.params.lateral_accel = v;
        }
        if let Some(v) = env_f("HORIZON") {
            spec.traffic.yield_horizon_s = v;
        }
        if let Some(v) = env_f("MARGIN") {
            spec.traffic.yield_margin_s = v;
        }
        if let Some(v) = env_f("SIGMA") {
            spec.traffic.sigma = v;
        }
        if let Some(v) = env_f("SPEED_DEV") {
            spec.traffic.speed_factor_dev = v;
        }
        if let Some(v) = env_f("HEADWAY") {
            spec.traffic.headway = v;
        }
        if let Some(v) = env_f("EMISSION") {
            spec.emission_per_s = v;
        }
        if let Some(v) = env_f("EMERGENCY") {
            spec.traffic.emergency_decel = v;
        }
        let sc = Arc::new(Scenario::compile(spec)?);
        let creep = sc.spec().occlusion.is_some();
        let set = if creep {
            ActionSet::Creep
        } else {
            ActionSet::Ttg
        };
        let t0 = std::time::Instant::now();
        let long: Vec<f64> = (0..=24).map(|i| f64::from(i) * 0.25).collect();
        let ts = if creep { &long } else { &thresholds };
        let tune = tune_ttc(&sc, set, creep, ts, trials, 7, &|_| {})?;
        println!("== {name} ({:.1} s)", t0.elapsed().as_secs_f64());
        for p in &tune.sweep {
            println!(
                "  thr {:5.2}  succ {:6.2}  coll {:5.2}  tout {:5.2}  time {:5.2}  brake {:4.2}",
                p.threshold,
                100.0 * p.success_rate,
                100.0 * p.collision_rate,
                100.0 * p.timeout_rate,
                p.mean_time_s.unwrap_or(f64::NAN),
                p.mean_brake_s
            );
        }
        println!("  best: {:?}", tune.best);
        if let (true, Some(best)) = (creep, tune.best) {
            let plain = crossroads_sim::TtcPolicy::new(best.threshold, false);
            let r = evaluate(&sc, &plain, &EvalConfig::new(set, trials, 7), &|_| {})?;
            println!(
                "  ttc without creep at {}: succ {:.2} coll {:.2} tout {:.2} time {:?}",
                best.threshold,
                100.0 * r.success_rate,
                100.0 * r.collision_rate,
                100.0 * r.timeout_rate,
                r.mean_time_s
            );
        }
        for set in [set, ActionSet::Sequential] {
            let r = evaluate(
                &sc,
                &RandomPolicy,
                &EvalConfig::new(set, trials, 7),
                &|_| {},
            )?;
            println!(
                "  random {set}: succ {:.2} coll {:.2} tout {:.2} time {:?} brake {:.2}",
                100.0 * r.success_rate,
                100.0 * r.collision_rate,
                100.0 * r.timeout_rate,
                r.mean_time_s,
                r.mean_brake_s
            );
        }
    }
    Ok(())
}
