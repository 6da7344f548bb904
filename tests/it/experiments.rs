//! The experiment configs in configs/experiments/: each is valid, states
//! what it simulates once (`[sim]`, no key of the older schema), and the
//! observation it resolves to is what its actors produce, so `crossroads
//! learner` and `crossroads actor` started from the same file agree.

use std::sync::Arc;

use crossroads_config::ConfigLoader;
use crossroads_sim::{ActionSet, Env, EnvConfig, Scenario};

#[test]
fn every_experiment_config_is_valid_and_consistent() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/experiments");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).expect("configs/experiments") {
        let path = entry.expect("entry").path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let c = ConfigLoader::new()
            .without_env()
            .file(Some(&path))
            .load()
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let text = std::fs::read_to_string(&path).expect("read");
        let table: toml::Table = text.parse().expect("toml");
        for (old, new) in crossroads_config::MOVED_KEYS {
            let (section, key) = old.split_once('.').expect("dotted");
            assert!(
                table.get(section).and_then(|s| s.get(key)).is_none(),
                "{} states `{old}`; write `{new}`",
                path.display()
            );
        }
        let mut sim = c.sim.clone();
        crossroads_actor::resolve_observation(&mut sim)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let scenario = Arc::new(Scenario::load(&c.sim.scenario).expect("scenario"));
        let actions: ActionSet = c.sim.action_set.parse().expect("action set");
        let env = Env::new(scenario, EnvConfig::for_actions(actions));
        let layout = env.obs_spec().layout();
        assert_eq!(
            sim.observation(),
            Some(layout.kind.as_str()),
            "{}",
            path.display()
        );
        assert_eq!(sim.layout(), Some(&layout), "{}", path.display());
        let stem = path
            .file_stem()
            .expect("stem")
            .to_string_lossy()
            .into_owned();
        let (base, variant) = stem
            .split_once('+')
            .map_or((stem.as_str(), None), |(b, v)| (b, Some(v)));
        assert_eq!(
            base,
            format!("{}-{}", c.sim.action_set, c.sim.scenario),
            "file names say <actions>-<scenario>, or <actions>-<scenario>+<variant>"
        );
        if let Some(variant) = variant {
            assert!(
                !variant.is_empty()
                    && variant
                        .chars()
                        .all(|ch| ch.is_ascii_lowercase() || ch.is_ascii_digit()),
                "{}: a variant is lowercase letters and digits",
                path.display()
            );
            assert!(
                dir.join(format!("{base}.toml")).is_file(),
                "{}: a variant of an experiment that does not exist",
                path.display()
            );
        }
        assert!(
            c.learner.max_updates > 0,
            "{} has no budget",
            path.display()
        );
        seen += 1;
    }
    assert_eq!(
        seen, 19,
        "5 TTG + 5 Sequential + 3 occlusion experiments, and 6 variants behind the shield \
         (5 TTG, 1 Creep)"
    );
}

/// A target's time bound is TTC's, and TTC's time is a measurement: it has
/// one home, the committed report, and the experiment files must follow it
/// when the report is made again (after a change of the simulator, say).
#[test]
fn every_target_follows_the_baselines_of_the_committed_report() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let report = root.join("reports/paper/results.json");
    let results: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&report).expect("reports/paper/results.json"),
    )
    .expect("results.json");
    let number = |v: &serde_json::Value, what: &str| {
        v.as_f64()
            .unwrap_or_else(|| panic!("{}: no number at {what}", report.display()))
    };
    let mut checked = 0;
    for e in crossroads_harness::experiments::EXPERIMENTS {
        let c = ConfigLoader::new()
            .without_env()
            .base(e.name, e.toml)
            .load()
            .unwrap_or_else(|err| panic!("{}: {err}", e.name));
        if c.train.target_success <= 0.0 {
            continue;
        }
        let row = results["table1"]
            .as_array()
            .expect("table1")
            .iter()
            .find(|r| r["scenario"] == c.sim.scenario.as_str());
        if let Some(row) = row {
            let ttc = number(&row["ttc"]["time"], "table1 ttc time");
            assert!(
                (c.train.target_time_s - ttc).abs() < 0.005,
                "{}: train.target_time_s = {} but TTC's mean time on {} is {ttc:.2} s in {}; \
                 write {ttc:.2}",
                e.name,
                c.train.target_time_s,
                c.sim.scenario,
                report.display()
            );
        } else {
            assert_eq!(c.sim.scenario, "occluded", "{}: no baseline", e.name);
            let cells: Vec<&serde_json::Value> = results["table2"]
                .as_array()
                .expect("table2")
                .iter()
                .map(|r| &r["ttc_creep"])
                .collect();
            let best = cells
                .iter()
                .map(|c| number(&c["success"], "table2 success"))
                .fold(f64::MIN, f64::max);
            let fastest = cells
                .iter()
                .map(|c| number(&c["time"], "table2 time"))
                .fold(f64::MAX, f64::min);
            assert!(
                c.train.target_success * 100.0 > best && c.train.target_time_s < fastest,
                "{}: the target ({} success, {} s) must beat TTC with creep in {} \
                 ({best:.2} % at best, {fastest:.2} s at fastest)",
                e.name,
                c.train.target_success,
                c.train.target_time_s,
                report.display()
            );
        }
        checked += 1;
    }
    assert_eq!(
        checked, 17,
        "15 Table I experiments, creep-occluded and creep-occluded+shield"
    );
}

#[test]
fn a_run_folder_is_named_after_its_experiment() {
    use crossroads_harness::train::default_out;
    for e in crossroads_harness::experiments::EXPERIMENTS {
        // A variant's run folder is its name too, from `--experiment`
        // (`train::run`); the flags alone name the base experiment's.
        let base = e.base();
        let (actions, scenario) = base.split_once('-').expect("<actions>-<scenario>");
        assert_eq!(
            default_out(scenario, actions),
            std::path::Path::new("runs").join(base)
        );
    }
    assert_eq!(
        default_out("my/own.toml", "creep"),
        std::path::Path::new("runs/creep-own")
    );
}
