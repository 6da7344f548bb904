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
        let kind = crossroads_actor::batch_spec(env.obs_spec()).kind;
        assert_eq!(sim.observation(), Some(kind.as_str()), "{}", path.display());
        let stem = path
            .file_stem()
            .expect("stem")
            .to_string_lossy()
            .into_owned();
        assert_eq!(
            stem,
            format!("{}-{}", c.sim.action_set, c.sim.scenario),
            "file names say <actions>-<scenario>"
        );
        assert!(
            c.learner.max_updates > 0,
            "{} has no budget",
            path.display()
        );
        seen += 1;
    }
    assert_eq!(seen, 13, "5 TTG + 5 Sequential + 3 occlusion experiments");
}
