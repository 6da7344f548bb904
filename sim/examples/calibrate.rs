//! Prints TTC sweeps, the tuned TTC row of Table I and random-policy
//! results, for calibrating the simulator against the paper.
//!
//! `cargo run --release -p crossroads-sim --example calibrate -- [trials] [scenario...]`
//!
//! Scenarios default to Table I's five. Occlusion scenarios (`occluded`,
//! `occluded-30`, ...) are swept with TTC with creep on Creep-and-Go
//! actions, and the tuned threshold is also run without creeping. Every
//! sweep uses seed 7 and thresholds 0 to 4 s (occlusion: 2 to 6 s) in
//! steps of 0.25 s; the tuned threshold is the lowest with no collision.
//!
//! Environment variables override parameters of every scenario, for trying
//! calibrations without editing files: `REACTION`, `YIELD_DECEL`, `MARGIN`,
//! `HORIZON`, `EMERGENCY`, `SIGMA`, `SPEED_DEV`, `HEADWAY` (traffic),
//! `EGO_ACCEL`, `LAT` (ego) and `EMISSION` (per lane).

use std::sync::Arc;

use crossroads_sim::{
    ActionSet, EvalConfig, RandomPolicy, Scenario, ScenarioSpec, SimError, TtcPolicy, evaluate,
    tune_ttc,
};

fn overrides(spec: &mut ScenarioSpec) {
    let var = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    let t = &mut spec.traffic;
    let traffic: [(&str, &mut f64); 8] = [
        ("REACTION", &mut t.reaction_delay_s),
        ("YIELD_DECEL", &mut t.yield_decel),
        ("MARGIN", &mut t.yield_margin_s),
        ("HORIZON", &mut t.yield_horizon_s),
        ("EMERGENCY", &mut t.emergency_decel),
        ("SIGMA", &mut t.sigma),
        ("SPEED_DEV", &mut t.speed_factor_dev),
        ("HEADWAY", &mut t.headway),
    ];
    for (k, field) in traffic {
        if let Some(v) = var(k) {
            *field = v;
        }
    }
    if let Some(v) = var("EGO_ACCEL") {
        spec.ego.params.accel = v;
    }
    if let Some(v) = var("LAT") {
        spec.ego.params.lateral_accel = v;
    }
    if let Some(v) = var("EMISSION") {
        spec.emission_per_s = v;
    }
}

fn main() -> Result<(), SimError> {
    let mut args = std::env::args().skip(1);
    let trials: u64 = args.next().and_then(|t| t.parse().ok()).unwrap_or(2000);
    let mut names: Vec<String> = args.collect();
    if names.is_empty() {
        names = ["right", "left", "left2", "forward", "challenge"]
            .map(String::from)
            .to_vec();
    }
    let mut rows = Vec::new();
    for name in &names {
        let mut spec = Scenario::load(name)?.spec().clone();
        overrides(&mut spec);
        let sc = Arc::new(Scenario::compile(spec)?);
        let creep = sc.spec().occlusion.is_some();
        let (set, first) = if creep {
            (ActionSet::Creep, 8)
        } else {
            (ActionSet::Ttg, 0)
        };
        let thresholds: Vec<f64> = (first..=first + 16).map(|i| f64::from(i) * 0.25).collect();
        let t0 = std::time::Instant::now();
        let tune = tune_ttc(&sc, set, creep, &thresholds, trials, 7, &|_| {})?;
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
        match tune.best {
            Some(b) => rows.push(format!(
                "{name:<12} {:>5.2} {:>7.2} {:>5.2} {:>6.2} {:>5.2}",
                b.threshold,
                100.0 * b.success_rate,
                100.0 * b.collision_rate,
                b.mean_time_s.unwrap_or(f64::NAN),
                b.mean_brake_s
            )),
            None => rows.push(format!("{name:<12} no threshold without collisions")),
        }
        if let (true, Some(best)) = (creep, tune.best) {
            let plain = TtcPolicy::new(best.threshold, false);
            let r = evaluate(&sc, &plain, &EvalConfig::new(set, trials, 7), &|_| {})?;
            println!(
                "  ttc without creep at {}: succ {:.2} coll {:.2} tout {:.2} time {:.2}",
                best.threshold,
                100.0 * r.success_rate,
                100.0 * r.collision_rate,
                100.0 * r.timeout_rate,
                r.mean_time_s.unwrap_or(f64::NAN)
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
                "  random {set}: succ {:.2} coll {:.2} tout {:.2} time {:.2} brake {:.2}",
                100.0 * r.success_rate,
                100.0 * r.collision_rate,
                100.0 * r.timeout_rate,
                r.mean_time_s.unwrap_or(f64::NAN),
                r.mean_brake_s
            );
        }
    }
    println!(
        "\nTTC, {trials} trials: scenario, threshold s, success %, collision %, time s, brake s"
    );
    for r in rows {
        println!("{r}");
    }
    Ok(())
}
