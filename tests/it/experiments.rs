//! The experiment configs in configs/experiments/: each is valid, and its
//! learner reads what its actors observe, so `crossroads learner` and
//! `crossroads actor` started from the same file agree.

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
        let scenario = Arc::new(Scenario::load(&c.actor.scenario).expect("scenario"));
        let actions: ActionSet = c.actor.action_set.parse().expect("action set");
        let env = Env::new(scenario, EnvConfig::for_actions(actions));
        let kind = crossroads_actor::batch_spec(env.obs_spec()).kind;
        assert_eq!(c.learner.observation, kind, "{}", path.display());
        assert_eq!(
            c.learner.action_set,
            c.actor.action_set,
            "{}",
            path.display()
        );
        assert_eq!(c.learner.scenario, c.actor.scenario, "{}", path.display());
        let stem = path
            .file_stem()
            .expect("stem")
            .to_string_lossy()
            .into_owned();
        assert_eq!(
            stem,
            format!("{}-{}", c.actor.action_set, c.actor.scenario),
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
