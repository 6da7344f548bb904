//! Layered config: file, environment, --set; errors name origin and key.

use std::io::Write;

use crossroads_config::{
    Config, ConfigError, ConfigLoader, DeviceSetting, LogFormat, PrecisionSetting,
};

fn toml_file(content: &str) -> tempfile::NamedTempFile {
    let mut f = tempfile::Builder::new()
        .suffix(".toml")
        .tempfile()
        .expect("temp file");
    f.write_all(content.as_bytes()).expect("write");
    f
}

/// Loads `content` as the config file, without the environment.
fn load(content: &str) -> (tempfile::NamedTempFile, Result<Config, ConfigError>) {
    let f = toml_file(content);
    let result = ConfigLoader::new()
        .without_env()
        .file(Some(f.path()))
        .load();
    (f, result)
}

fn problems(err: &ConfigError) -> Vec<(String, String, String)> {
    err.problems()
        .iter()
        .map(|p| (p.origin.clone(), p.key.clone(), p.problem.clone()))
        .collect()
}

#[test]
fn defaults_load_and_validate() {
    let config = ConfigLoader::new().without_env().load().expect("defaults");
    assert_eq!(config.runtime.worker_threads, 2);
    assert_eq!(config.telemetry.log_format, LogFormat::Text);
    assert!(config.validate().is_empty());
}

#[test]
fn file_values_override_defaults() {
    let (_f, result) = load("[runtime]\nworker_threads = 6\n[telemetry]\nlog_format = \"json\"\n");
    let config = result.expect("valid file");
    assert_eq!(config.runtime.worker_threads, 6);
    assert_eq!(config.runtime.compute_threads, 0, "untouched default");
    assert_eq!(config.telemetry.log_format, LogFormat::Json);
}

#[test]
fn networks_run_on_one_libtorch_thread_unless_told_otherwise() {
    let (_f, result) = load("");
    let config = result.expect("empty file");
    assert_eq!(config.runtime.torch_threads(), Some(1));
    let (_f, result) = load("[runtime]\ntorch_threads = 0\ncompute_threads = 3\n");
    assert_eq!(result.expect("valid").runtime.torch_threads(), Some(3));
    let (_f, result) = load("[runtime]\ntorch_threads = 0\n");
    assert_eq!(
        result.expect("valid").runtime.torch_threads(),
        None,
        "libtorch's own choice"
    );
    let (_f, result) = load("[runtime]\ntorch_threads = 4000\n");
    let err = format!("{:#}", result.expect_err("out of range"));
    assert!(err.contains("runtime.torch_threads"), "{err}");
}

#[test]
fn the_learner_follows_torch_threads_unless_given_its_own() {
    let (_f, result) = load("[runtime]\ntorch_threads = 3\n");
    assert_eq!(
        result.expect("valid").runtime.learner_torch_threads(),
        Some(3)
    );
    let (_f, result) = load("[runtime]\nlearner_torch_threads = 2\n");
    let runtime = result.expect("valid").runtime;
    assert_eq!(
        (runtime.torch_threads(), runtime.learner_torch_threads()),
        (Some(1), Some(2)),
        "actors keep one"
    );
    let (_f, result) = load("[runtime]\nlearner_torch_threads = 4000\n");
    let err = format!("{:#}", result.expect_err("out of range"));
    assert!(err.contains("runtime.learner_torch_threads"), "{err}");
}

#[test]
fn precision_is_auto_unless_told_and_names_a_wrong_value() {
    let (_f, result) = load("");
    assert_eq!(
        result.expect("empty file").runtime.precision,
        PrecisionSetting::Auto
    );
    let (_f, result) = load("[runtime]\nprecision = \"f32\"\n");
    assert_eq!(
        result.expect("valid").runtime.precision,
        PrecisionSetting::F32
    );
    let (_f, result) = load("[runtime]\nprecision = \"fp16\"\n");
    let err = format!("{:#}", result.expect_err("no such format"));
    assert!(err.contains("runtime.precision"), "{err}");
    assert_eq!("bf16".parse(), Ok(PrecisionSetting::Bf16));
    assert!("half".parse::<PrecisionSetting>().is_err());
}

#[test]
fn device_is_auto_unless_told_and_names_a_wrong_value() {
    let (_f, result) = load("");
    let config = result.expect("empty file");
    assert_eq!(config.runtime.device, DeviceSetting::Auto);
    let (_f, result) = load("[runtime]\ndevice = \"cpu\"\n");
    assert_eq!(result.expect("valid").runtime.device, DeviceSetting::Cpu);
    let (_f, result) = load("[runtime]\ndevice = \"gpu\"\n");
    let err = format!("{:#}", result.expect_err("no such device"));
    assert!(err.contains("runtime.device"), "{err}");

    // From the command line; validation is pure, so `cuda` loads and
    // validates on a machine without one (the learner says so at start).
    let config = ConfigLoader::new()
        .without_env()
        .sets(["runtime.device=cuda"])
        .load()
        .expect("valid");
    assert_eq!(config.runtime.device, DeviceSetting::Cuda);
    assert!(config.validate().is_empty());
    assert!(config.to_toml().contains("device = \"cuda\""));

    assert_eq!("cuda".parse(), Ok(DeviceSetting::Cuda));
    assert_eq!("auto".parse(), Ok(DeviceSetting::Auto));
    assert!("gpu".parse::<DeviceSetting>().is_err());
    for d in [DeviceSetting::Auto, DeviceSetting::Cpu, DeviceSetting::Cuda] {
        assert_eq!(d.name().parse(), Ok(d));
    }
}

#[test]
fn unknown_key_names_file_and_key() {
    let (f, result) = load("[runtime]\nworker_thread = 3\n");
    let err = result.expect_err("unknown key");
    let p = problems(&err);
    assert_eq!(p.len(), 1, "{p:?}");
    let (origin, key, problem) = &p[0];
    assert_eq!(key, "runtime.worker_thread");
    assert!(origin.contains(&f.path().display().to_string()), "{origin}");
    assert!(problem.contains("unknown key"), "{problem}");
    assert!(
        problem.contains("worker_threads"),
        "suggests the real keys: {problem}"
    );
}

#[test]
fn unknown_section_names_the_section() {
    let (_f, result) = load("[learnr]\nbatch_size = 3\n");
    let err = result.expect_err("unknown section");
    let p = problems(&err);
    assert_eq!(p[0].1, "learnr", "{p:?}");
}

#[test]
fn wrong_type_names_file_and_key() {
    let (_f, result) = load("[runtime]\nworker_threads = \"many\"\n");
    let err = result.expect_err("wrong type");
    let message = err.to_string();
    let p = problems(&err);
    assert_eq!(p[0].1, "runtime.worker_threads", "{p:?}");
    assert!(p[0].0.contains("config file"), "{p:?}");
    assert!(p[0].2.contains("invalid type"), "{p:?}");
    assert!(message.contains("runtime.worker_threads"), "{message}");
}

#[test]
fn out_of_range_value_names_file_key_and_range() {
    let (f, result) = load("[runtime]\nworker_threads = 0\n");
    let err = result.expect_err("out of range");
    let p = problems(&err);
    assert_eq!(p.len(), 1, "{p:?}");
    assert_eq!(p[0].1, "runtime.worker_threads");
    assert!(p[0].0.contains(&f.path().display().to_string()), "{p:?}");
    assert!(p[0].2.contains("between 1 and 256"), "{p:?}");
}

#[test]
fn enum_value_outside_the_choices_is_named() {
    let (_f, result) = load("[telemetry]\nlog_format = \"xml\"\n");
    let err = result.expect_err("bad enum");
    let p = problems(&err);
    assert_eq!(p[0].1, "telemetry.log_format", "{p:?}");
    assert!(p[0].2.contains("xml"), "{p:?}");
}

#[test]
fn set_overrides_file_and_errors_name_the_command_line() {
    let f = toml_file("[runtime]\nworker_threads = 6\n");
    let config = ConfigLoader::new()
        .without_env()
        .file(Some(f.path()))
        .sets(["runtime.worker_threads=3"])
        .load()
        .expect("valid");
    assert_eq!(config.runtime.worker_threads, 3);

    let err = ConfigLoader::new()
        .without_env()
        .file(Some(f.path()))
        .sets(["runtime.worker_threads=999"])
        .load()
        .expect_err("out of range from --set");
    let p = problems(&err);
    assert_eq!(p[0].0, "command line", "{p:?}");
    assert_eq!(p[0].1, "runtime.worker_threads");

    let err = ConfigLoader::new()
        .without_env()
        .sets(["runtime.worker_threads"])
        .load()
        .expect_err("no =");
    assert!(matches!(err, ConfigError::BadOverride(_)), "{err}");
}

#[test]
fn missing_file_is_an_error_naming_it() {
    let err = ConfigLoader::new()
        .without_env()
        .file(Some("/nonexistent/crossroads.toml"))
        .load()
        .expect_err("missing");
    assert!(
        err.to_string().contains("/nonexistent/crossroads.toml"),
        "{err}"
    );
}

#[test]
fn malformed_toml_is_an_error_naming_the_file() {
    let (f, result) = load("[runtime\nworker_threads = 2\n");
    let err = result.expect_err("syntax error");
    assert!(
        err.to_string().contains(&f.path().display().to_string()),
        "{err}"
    );
}

#[test]
fn rendered_config_loads_back_identically() {
    let config = ConfigLoader::new()
        .without_env()
        .sets(["runtime.compute_threads=3", "telemetry.metrics=false"])
        .load()
        .expect("valid");
    let (_f, result) = load(&config.to_toml());
    let back = result.expect("round trip");
    assert_eq!(config, back);
}

#[test]
fn replay_and_transport_sections_have_valid_defaults_and_checked_ranges() {
    let config = ConfigLoader::new().without_env().load().expect("defaults");
    assert_eq!(config.replay.capacity, 1_000_000);
    assert_eq!(config.transport.replay_endpoint, "http://127.0.0.1:50051");

    let err = ConfigLoader::new()
        .without_env()
        .sets([
            "replay.capacity=0",
            "replay.alpha=1.5",
            "replay.samples_per_insert=8.0",
            "replay.rate_tolerance=2.0",
            "transport.replay_endpoint=replay:50051",
        ])
        .load()
        .expect_err("out of range");
    let keys: Vec<String> = problems(&err).into_iter().map(|p| p.1).collect();
    for key in [
        "replay.capacity",
        "replay.alpha",
        "replay.rate_tolerance",
        "transport.replay_endpoint",
    ] {
        assert!(keys.iter().any(|k| k == key), "{key} missing from {keys:?}");
    }

    let f = toml_file(
        "[replay]\ncapacity = 5\nsnapshot_dir = \"/tmp/x\"\n[transport]\nshm_prefix = \"bad prefix\"\n",
    );
    let err = ConfigLoader::new()
        .without_env()
        .file(Some(f.path()))
        .load()
        .expect_err("bad prefix");
    let p = problems(&err);
    assert_eq!(p.len(), 1, "{p:?}");
    assert_eq!(p[0].1, "transport.shm_prefix");
    assert!(p[0].0.contains("config file"), "{p:?}");

    let config = ConfigLoader::new()
        .without_env()
        .flag("replay.capacity", 5000u64)
        .flag("replay.snapshot_dir", "/var/lib/replay")
        .flag("replay.listen", "0.0.0.0:0")
        .load()
        .expect("flags");
    assert_eq!(config.replay.capacity, 5000);
    assert_eq!(
        config.replay.snapshot_dir.as_deref(),
        Some(std::path::Path::new("/var/lib/replay"))
    );
    assert_eq!(config.replay.listen.port(), 0);
}

/// A file of the older schema: scenario and action set under both
/// `[actor]` and `[learner]`, the observation under `[learner]`, the actor
/// count as `train.actors`.
const OLD_SCHEMA: &str = r#"
[actor]
scenario = "right"
action_set = "sequential"
envs = 4

[learner]
scenario = "right"
observation = "sequential"
action_set = "sequential"

[train]
actors = 3
"#;

#[test]
fn old_schema_files_load_with_a_warning_per_moved_key() {
    let f = toml_file(OLD_SCHEMA);
    let (config, notes) = ConfigLoader::new()
        .without_env()
        .file(Some(f.path()))
        .load_with_notes()
        .expect("an old file still loads");
    assert_eq!(config.sim.scenario, "right");
    assert_eq!(config.sim.action_set, "sequential");
    assert_eq!(config.sim.observation(), Some("sequential"));
    assert_eq!(config.actor.count, 3);
    assert_eq!(config.actor.envs, 4, "other keys untouched");
    assert_eq!(notes.len(), 6, "{notes:#?}");
    for (old, new) in crossroads_config::MOVED_KEYS {
        assert!(
            notes
                .iter()
                .any(|n| n.contains(&format!("`{old}`")) && n.contains(&format!("`{new}`"))),
            "no warning for {old}: {notes:#?}"
        );
    }
    assert!(notes[0].contains("config file"), "{}", notes[0]);
    // The effective config is written in the new schema only.
    let shown = config.to_toml();
    assert!(shown.contains("[sim]"), "{shown}");
    assert!(!shown.contains("actors ="), "{shown}");
}

#[test]
fn a_current_file_loads_without_warnings() {
    let f = toml_file("[sim]\nscenario = \"right\"\n[actor]\ncount = 2\n");
    let (config, notes) = ConfigLoader::new()
        .without_env()
        .file(Some(f.path()))
        .load_with_notes()
        .expect("valid");
    assert!(notes.is_empty(), "{notes:#?}");
    assert_eq!(config.sim.scenario, "right");
    assert_eq!(config.sim.observation(), None, "derived by the roles");
}

#[test]
fn old_keys_that_disagree_are_refused_naming_both() {
    let (_f, result) = load("[actor]\nscenario = \"left\"\n[learner]\nscenario = \"right\"\n");
    let err = result.expect_err("two scenarios");
    let text = err.to_string();
    assert!(text.contains("actor.scenario"), "{text}");
    assert!(text.contains("learner.scenario"), "{text}");
    assert!(text.contains("sim.scenario"), "{text}");
    assert!(
        text.contains("\"left\"") && text.contains("\"right\""),
        "{text}"
    );
}

#[test]
fn an_old_key_that_contradicts_the_new_one_is_refused() {
    let (_f, result) = load("[sim]\naction_set = \"creep\"\n[actor]\naction_set = \"ttg\"\n");
    let err = result.expect_err("two action sets");
    let p = problems(&err);
    assert_eq!(p.len(), 1, "{p:#?}");
    assert_eq!(p[0].1, "actor.action_set");
    assert!(p[0].0.starts_with("config file"), "{p:#?}");
    assert!(
        p[0].2.contains("sim.action_set") && p[0].2.contains("remove"),
        "{p:#?}"
    );
    // The same value in both places is only redundant.
    let (_f, result) = load("[sim]\naction_set = \"creep\"\n[actor]\naction_set = \"creep\"\n");
    assert_eq!(result.expect("agrees").sim.action_set, "creep");
}

#[test]
fn an_old_key_from_the_environment_or_set_flag_is_moved_too() {
    let config = ConfigLoader::new()
        .without_env()
        .sets(["train.actors=5", "learner.observation=ttg-occlusion"])
        .load()
        .expect("loads");
    assert_eq!(config.actor.count, 5);
    assert_eq!(config.sim.observation(), Some("ttg-occlusion"));
}

#[test]
fn the_run_configs_committed_before_the_sim_section_still_load() {
    let runs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../reports/paper/runs");
    let mut seen = 0;
    for entry in std::fs::read_dir(&runs).expect("reports/paper/runs") {
        let path = entry.expect("entry").path().join("config.toml");
        if !path.exists() {
            continue;
        }
        let text = std::fs::read_to_string(&path).expect("read");
        let old: toml::Table = text.parse().expect("toml");
        let (config, _) = ConfigLoader::new()
            .without_env()
            .file(Some(&path))
            .load_with_notes()
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        if let Some(scenario) = old
            .get("actor")
            .and_then(|a| a.get("scenario"))
            .and_then(|s| s.as_str())
        {
            assert_eq!(config.sim.scenario, scenario, "{}", path.display());
        }
        seen += 1;
    }
    assert!(seen >= 10, "only {seen} run configs found");
}

#[test]
fn between_an_old_key_and_its_new_one_the_later_layer_wins() {
    // A built-in experiment states the new key; an old key on the command
    // line overrides it, as any later layer does.
    let config = ConfigLoader::new()
        .without_env()
        .base("experiment", "[sim]\nscenario = \"left\"\n")
        .sets(["actor.scenario=occluded-30"])
        .load()
        .expect("the command line wins");
    assert_eq!(config.sim.scenario, "occluded-30");
    // The new key on the command line overrides an old one in the file.
    let f = toml_file("[actor]\nscenario = \"right\"\n");
    let (config, notes) = ConfigLoader::new()
        .without_env()
        .file(Some(f.path()))
        .sets(["sim.scenario=left2"])
        .load_with_notes()
        .expect("the command line wins");
    assert_eq!(config.sim.scenario, "left2");
    assert!(
        notes[0].contains("overridden by `sim.scenario`"),
        "{notes:#?}"
    );
}

/// The config's own checks, before any file is read: pairs, https without
/// a CA, TLS servers behind http:// endpoints, the removed token key.
#[test]
fn security_settings_are_checked_when_the_config_loads() {
    let problems = |sets: &[&str]| -> Vec<(String, String)> {
        ConfigLoader::new()
            .without_env()
            .sets(sets.iter().copied())
            .load()
            .expect_err("invalid")
            .problems()
            .iter()
            .map(|p| (p.key.clone(), p.problem.clone()))
            .collect()
    };
    let has = |p: &[(String, String)], key: &str, says: &str| {
        assert!(
            p.iter().any(|(k, m)| k == key && m.contains(says)),
            "no {key:?} saying {says:?} in {p:?}"
        );
    };
    let p = problems(&["transport.replay_endpoint=https://replay:50051"]);
    has(&p, "transport.tls.ca_file", "https://replay:50051");
    let p = problems(&["transport.tls.cert_file=/tls/server.pem"]);
    has(&p, "transport.tls.key_file", "transport.tls.cert_file");
    has(&p, "transport.replay_endpoint", "https://");
    has(&p, "transport.learner_endpoint", "https://");
    let p = problems(&["transport.tls.client_ca_file=/tls/ca.pem"]);
    has(&p, "transport.tls.client_ca_file", "cert_file");
    let p = problems(&["transport.tls.client_cert_file=/tls/client.pem"]);
    has(&p, "transport.tls.client_key_file", "client_cert_file");
    let p = problems(&["transport.auth.token_env=NOT A NAME"]);
    has(&p, "transport.auth.token_env", "environment variable name");
    let p = problems(&["learner.api_token=s3cret"]);
    has(&p, "learner.api_token", "transport.auth.token_file");

    // A whole secure run's settings load, without reading the files.
    let config = ConfigLoader::new()
        .without_env()
        .sets([
            "transport.replay_endpoint=https://replay:50051",
            "transport.learner_endpoint=https://learner:50052",
            "transport.tls.cert_file=/tls/server.pem",
            "transport.tls.key_file=/tls/server.key",
            "transport.tls.client_ca_file=/tls/ca.pem",
            "transport.tls.ca_file=/tls/ca.pem",
            "transport.tls.client_cert_file=/tls/client.pem",
            "transport.tls.client_key_file=/tls/client.key",
            "transport.auth.token_file=/tls/token",
        ])
        .load()
        .expect("valid");
    assert!(config.transport.tls.serves_tls());
    assert!(!config.to_toml().contains("api_token"));
}

/// `learner.go_label_weight` weighs the absorbing go of ttg and creep:
/// above 0, and only 1 where the action set has no such go.
#[test]
fn the_go_label_weight_needs_an_absorbing_go() {
    let config = ConfigLoader::new()
        .without_env()
        .sets(["sim.action_set=creep", "learner.go_label_weight=5"])
        .load()
        .expect("creep has an absorbing go");
    assert_eq!(config.learner.go_label_weight, 5.0);
    for (sets, says) in [
        (
            ["sim.action_set=ttg", "learner.go_label_weight=0"],
            "above 0",
        ),
        (
            ["sim.action_set=sequential", "learner.go_label_weight=5"],
            "no absorbing go",
        ),
    ] {
        let err = ConfigLoader::new()
            .without_env()
            .sets(sets)
            .load()
            .expect_err("refused");
        let p = problems(&err);
        assert!(
            p.iter()
                .any(|(_, k, m)| k == "learner.go_label_weight" && m.contains(says)),
            "{says} missing from {p:?}"
        );
    }
}

#[test]
fn early_phases_of_the_replay_ratio_and_the_learner_are_checked() {
    let config = ConfigLoader::new()
        .without_env()
        .sets([
            "replay.samples_per_insert=4.0",
            "replay.rate_tolerance=20000.0",
            "replay.early_samples_per_insert=0.25",
            "replay.ratio_ramp=[192000,640000]",
            "learner.early_updates=3000",
            "learner.early_learning_rate=0.001",
            "learner.early_target_period=250",
        ])
        .load()
        .expect("an early phase");
    assert_eq!(config.replay.early_samples_per_insert, Some(0.25));
    assert_eq!(config.replay.ratio_ramp, [192_000, 640_000]);
    assert_eq!(config.learner.early_learning_rate, Some(0.001));
    assert_eq!(config.learner.early_target_period, Some(250));

    let err = ConfigLoader::new()
        .without_env()
        .sets([
            "replay.samples_per_insert=0.0",
            "replay.early_samples_per_insert=-1.0",
            "replay.ratio_ramp=[10,5]",
            "learner.early_learning_rate=0.0",
            "learner.early_target_period=0",
        ])
        .load()
        .expect_err("out of range");
    let p = problems(&err);
    for (key, says) in [
        ("replay.early_samples_per_insert", "above 0"),
        (
            "replay.early_samples_per_insert",
            "needs replay.samples_per_insert",
        ),
        ("replay.ratio_ramp", "from at most to"),
        ("learner.early_learning_rate", "above 0"),
        ("learner.early_target_period", "at least 1"),
    ] {
        assert!(
            p.iter().any(|(_, k, m)| k == key && m.contains(says)),
            "{key}: {says} missing from {p:?}"
        );
    }

    // The tolerance must cover the early ratio too.
    let err = ConfigLoader::new()
        .without_env()
        .sets([
            "replay.samples_per_insert=1.0",
            "replay.rate_tolerance=2.0",
            "replay.early_samples_per_insert=8.0",
        ])
        .load()
        .expect_err("tolerance below the early ratio");
    assert!(
        problems(&err)
            .iter()
            .any(|(_, k, _)| k == "replay.rate_tolerance"),
        "{:?}",
        problems(&err)
    );
}
