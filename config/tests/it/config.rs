//! Layered config: file, environment, --set; errors name origin and key.

use std::io::Write;

use crossroads_config::{Config, ConfigError, ConfigLoader, LogFormat};

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
