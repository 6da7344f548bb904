//! The `crossroads` binary as a user runs it.

use std::process::Output;

use clap::CommandFactory;
use crossroads::cli::Cli;

/// `crossroads args` at the binary's default log level.
fn crossroads(args: &[&str]) -> Output {
    crate::crossroads()
        .command()
        .args(args)
        .env_remove("RUST_LOG")
        .output()
        .expect("run crossroads")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn clap_definition_is_consistent() {
    // The command line as parsed: every key table names flags that exist.
    crossroads::cli::command().debug_assert();
}

#[test]
fn help_describes_the_program_and_every_subcommand() {
    let out = crossroads(&["--help"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let help = stdout(&out);
    assert!(help.contains("intersections"), "{help}");
    let cli = Cli::command();
    let subcommands: Vec<_> = cli.get_subcommands().collect();
    assert!(!subcommands.is_empty());
    for sub in subcommands {
        let name = sub.get_name();
        let about = sub
            .get_about()
            .map(ToString::to_string)
            .unwrap_or_else(|| panic!("subcommand {name} has no description"));
        assert!(help.contains(name), "{name} missing from --help:\n{help}");

        let out = crossroads(&[name, "--help"]);
        assert!(out.status.success(), "{name} --help: {}", stderr(&out));
        let sub_help = stdout(&out);
        // Help text is wrapped to the terminal width; compare words.
        let words = |s: &str| s.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(
            words(&sub_help).contains(&words(&about)),
            "{name} --help lacks {about:?}:\n{sub_help}"
        );
        for nested in sub.get_subcommands() {
            let nested_name = nested.get_name();
            let out = crossroads(&[name, nested_name, "--help"]);
            assert!(out.status.success(), "{name} {nested_name} --help");
            let nested_about = nested
                .get_about()
                .map(ToString::to_string)
                .unwrap_or_else(|| panic!("{name} {nested_name} has no description"));
            assert!(
                words(&stdout(&out)).contains(&words(&nested_about)),
                "{name} {nested_name} --help lacks {nested_about:?}"
            );
        }
    }
}

#[test]
fn config_show_prints_toml_with_layers_applied() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("run.toml");
    std::fs::write(
        &file,
        "[runtime]\nworker_threads = 5\ncompute_threads = 1\n",
    )
    .expect("write");
    let out = crate::crossroads()
        .command()
        .args(["--config", file.to_str().expect("utf-8 path")])
        .args(["--set", "runtime.compute_threads=3", "config", "show"])
        .args(["--set", "actor.envs=12"])
        .env("CROSSROADS_TELEMETRY__LOG_FORMAT", "json")
        .output()
        .expect("run");
    assert!(out.status.success(), "{}", stderr(&out));
    let shown: toml::Value = toml::from_str(&stdout(&out)).expect("stdout is TOML");
    assert_eq!(
        shown["runtime"]["worker_threads"].as_integer(),
        Some(5),
        "from the file"
    );
    assert_eq!(
        shown["runtime"]["compute_threads"].as_integer(),
        Some(3),
        "--set wins"
    );
    assert_eq!(
        shown["telemetry"]["log_format"].as_str(),
        Some("json"),
        "from the environment"
    );
    assert_eq!(
        shown["actor"]["envs"].as_integer(),
        Some(12),
        "a --set after the subcommand adds to those before it"
    );
}

/// A container picks the paper's tuned settings by name, under the
/// environment and --set; a wrong name lists the right ones.
#[test]
fn a_built_in_experiment_is_the_base_of_any_role() {
    let out = crossroads(&[
        "--experiment",
        "sequential-right",
        "config",
        "show",
        "--set",
        "learner.batch_size=32",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let shown: toml::Value = toml::from_str(&stdout(&out)).expect("stdout is TOML");
    assert_eq!(shown["sim"]["scenario"].as_str(), Some("right"));
    assert_eq!(shown["sim"]["action_set"].as_str(), Some("sequential"));
    assert_eq!(shown["learner"]["max_updates"].as_integer(), Some(120_000));
    assert_eq!(
        shown["learner"]["batch_size"].as_integer(),
        Some(32),
        "--set wins"
    );

    let out = crate::crossroads()
        .command()
        .args(["config", "show"])
        .env("CROSSROADS_EXPERIMENT", "ttg-nowhere")
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("no built-in experiment \"ttg-nowhere\"")
            && err.contains("ttg-left, ttg-left2"),
        "{err}"
    );
}

#[test]
fn bad_config_fails_with_an_error_naming_the_key() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("bad.toml");
    std::fs::write(&file, "[runtime]\nworker_threads = 0\n").expect("write");
    let out = crossroads(&[
        "--config",
        file.to_str().expect("utf-8 path"),
        "config",
        "check",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("runtime.worker_threads"), "{err}");
    assert!(err.contains("bad.toml"), "{err}");

    let out = crate::crossroads()
        .command()
        .args(["config", "check"])
        .env("CROSSROADS_RUNTIME__WORKER_THREADS", "lots")
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("CROSSROADS_RUNTIME__WORKER_THREADS"), "{err}");
}

#[test]
fn doctor_times_the_network_a_run_would_train() {
    let out = crossroads(&["doctor", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).expect("JSON");
    assert!(report["cores"].as_u64().is_some_and(|c| c >= 1), "{report}");
    assert!(
        report["torch_threads"].as_i64().is_some_and(|t| t >= 1),
        "{report}"
    );
    // Without a file: what `crossroads train` trains by default, the
    // built-in ttg-left (conv trunk over the TTG grid, 64 environments per
    // actor, batches of 64).
    assert_eq!(report["config"], "built-in experiment ttg-left", "{report}");
    assert_eq!(
        report["network"], "dueling conv 2344-16-32-256 -> 5",
        "{report}"
    );
    assert_eq!(
        (
            report["actor_batch"].as_u64(),
            report["learner_batch"].as_u64()
        ),
        (Some(64), Some(64)),
        "{report}"
    );
    for key in [
        "actor_forward_median_ms",
        "learner_forward_median_ms",
        "learner_update_median_ms",
    ] {
        let ms = report[key].as_f64().expect("timing");
        assert!(ms > 0.0 && ms.is_finite(), "{key}: {report}");
    }

    // The loaded layers decide: another network and batch sizes, and the
    // observation follows the scenario (occlusion adds a channel: 6 x 18 x
    // 26 + 4 inputs).
    let out = crossroads(&[
        "--set",
        "learner.trunk=mlp",
        "--set",
        "learner.hidden=[32]",
        "--set",
        "learner.batch_size=8",
        "--set",
        "actor.envs=4",
        "--set",
        "sim.scenario=occluded-30",
        "doctor",
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).expect("JSON");
    assert_eq!(
        (
            report["actor_batch"].as_u64(),
            report["learner_batch"].as_u64()
        ),
        (Some(4), Some(8)),
        "{report}"
    );
    assert_eq!(report["network"], "dueling mlp 2812-32 -> 5", "{report}");
}

/// `crossroads doctor --json` of a small network, with each variable of
/// `vars` set or (None) removed, and the report.
fn doctor_with(vars: &[(&str, Option<&str>)], extra: &[&str]) -> serde_json::Value {
    let mut c = crate::crossroads().command();
    c.args(["--set", "learner.trunk=mlp", "--set", "learner.hidden=[32]"])
        .args(["doctor", "--json"])
        .args(extra);
    for (var, value) in vars {
        match value {
            Some(v) => c.env(var, v),
            None => c.env_remove(var),
        };
    }
    let out = c.output().expect("run crossroads doctor");
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_str(&stdout(&out)).expect("JSON")
}

/// `doctor_with` `OMP_WAIT_POLICY` as given and `GLIBC_TUNABLES` unset.
fn doctor_with_wait_policy(policy: Option<&str>, extra: &[&str]) -> serde_json::Value {
    doctor_with(
        &[("OMP_WAIT_POLICY", policy), ("GLIBC_TUNABLES", None)],
        extra,
    )
}

/// libgomp reads its wait policy and glibc its heap thresholds before
/// `main`; the binary re-executes itself with the passive policy and the
/// thresholds unless the user chose them.
#[test]
fn every_command_runs_with_passive_openmp_threads_unless_the_user_chose() {
    let report = doctor_with_wait_policy(None, &[]);
    assert_eq!(report["openmp_wait_policy"], "passive", "{report}");
    let tunables = report["glibc_tunables"].as_str().expect("a string");
    assert!(
        tunables.contains("glibc.malloc.trim_threshold=")
            && tunables.contains("glibc.malloc.mmap_threshold="),
        "{report}"
    );
    let report = doctor_with_wait_policy(Some("active"), &[]);
    assert_eq!(report["openmp_wait_policy"], "active", "{report}");
    // The user's own tunables stay as they are, and the policy still
    // becomes passive.
    let report = doctor_with(
        &[
            ("OMP_WAIT_POLICY", None),
            ("GLIBC_TUNABLES", Some("glibc.malloc.arena_max=2")),
        ],
        &[],
    );
    assert_eq!(
        report["glibc_tunables"], "glibc.malloc.arena_max=2",
        "{report}"
    );
    assert_eq!(report["openmp_wait_policy"], "passive", "{report}");
}

/// Beside a process spinning on one of the cores, a forward pass is not
/// much slower than quiet. With libgomp's spinning threads it collapsed
/// (reports/performance/README.md, "OpenMP wait policy"); losing a core's
/// share costs at most 2x; the bound leaves room for the noise of tests
/// running side by side, not for the collapse.
#[test]
fn a_busy_core_does_not_collapse_the_forward_pass() {
    let report = doctor_with_wait_policy(None, &["--busy"]);
    let busy = &report["busy"];
    for key in ["actor_forward_ratio", "learner_forward_ratio"] {
        let ratio = busy[key].as_f64().expect("a ratio");
        assert!(ratio.is_finite() && ratio > 0.0, "{key}: {report}");
        assert!(ratio < 6.0, "{key} {ratio:.1}x: {report}");
    }
}

/// `doctor` says what CUDA it found and the device the learner would
/// train on (`runtime.device`, `auto` by default); `cuda` where it cannot
/// be had fails the check (status 1), naming what is missing.
#[test]
fn doctor_reports_the_learner_device_and_fails_a_cuda_it_cannot_have() {
    let report = doctor_with(&[], &[]);
    let devices = report["cuda_devices"].as_i64().expect("a count");
    let cuda = report["libtorch_cuda"].as_bool().expect("a flag") && devices > 0;
    assert!(report["cudnn"].is_boolean(), "{report}");
    assert_eq!(report["device_setting"], "auto", "{report}");
    assert_eq!(
        report["learner_device"],
        if cuda { "cuda:0" } else { "cpu" },
        "{report}"
    );
    assert!(report.get("learner_device_error").is_none(), "{report}");
    if cuda {
        return;
    }
    let out = crossroads(&[
        "--set",
        "learner.trunk=mlp",
        "--set",
        "learner.hidden=[32]",
        "--set",
        "runtime.device=cuda",
        "doctor",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&stdout(&out)).expect("JSON");
    assert_eq!(report["learner_device"], "unavailable", "{report}");
    let error = report["learner_device_error"].as_str().expect("the reason");
    assert!(
        error.contains("runtime.device = \"cuda\"")
            && (error.contains("built without CUDA") || error.contains("no CUDA device")),
        "{error}"
    );
}

/// A config file of the older schema still runs, with a warning per moved
/// key on standard error; the effective configuration is the new schema.
#[test]
fn an_old_schema_config_loads_with_warnings_saying_what_to_write() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("old.toml");
    std::fs::write(
        &file,
        "[actor]\nscenario = \"left2\"\naction_set = \"ttg\"\n\
         [learner]\nscenario = \"left2\"\nobservation = \"ttg\"\naction_set = \"ttg\"\n\
         [train]\nactors = 3\n",
    )
    .expect("write");
    let out = crossroads(&["--config", file.to_str().expect("utf-8"), "config", "show"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("`actor.scenario` is deprecated") && err.contains("`sim.scenario`"),
        "{err}"
    );
    assert!(
        err.contains("`train.actors`") && err.contains("`actor.count`"),
        "{err}"
    );
    let shown: toml::Value = toml::from_str(&stdout(&out)).expect("stdout is TOML");
    assert_eq!(shown["sim"]["scenario"].as_str(), Some("left2"));
    assert_eq!(shown["actor"]["count"].as_integer(), Some(3));
    assert!(shown["actor"].get("scenario").is_none(), "{shown}");

    // Two scenarios for one run are refused, naming both keys.
    std::fs::write(
        &file,
        "[actor]\nscenario = \"left\"\n[learner]\nscenario = \"right\"\n",
    )
    .expect("write");
    let out = crossroads(&["--config", file.to_str().expect("utf-8"), "config", "show"]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("actor.scenario")
            && err.contains("learner.scenario")
            && err.contains("sim.scenario"),
        "{err}"
    );
}

/// A stated observation that is not what the actors of the scenario and
/// action set produce is refused at start, saying what they produce.
#[test]
fn a_mismatched_observation_is_refused_by_every_role() {
    let out = crossroads(&[
        "--set",
        "sim.scenario=occluded",
        "--set",
        "sim.observation=ttg",
        "bench",
        "learner",
        "--rounds",
        "1",
    ]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("ttg-occlusion") && err.contains("sim.observation"),
        "{err}"
    );
}

/// `bench time-to-target` trains each seed into its own folder and reads
/// the confirmed target from its summary. The target here is one the
/// untrained network meets (10 % success over 50 trials), so the test
/// checks the plumbing in seconds, not learning.
#[test]
fn bench_time_to_target_trains_each_seed_and_reports_medians() {
    let out = tempfile::tempdir().expect("temp dir");
    let folder = out.path().join("runs");
    let folder_arg = folder.display().to_string();
    let result = crossroads(&[
        "--set",
        "train.target_success=0.01",
        "--set",
        "train.target_collision=1",
        "--set",
        "train.eval_trials=50",
        "--set",
        "train.confirm_trials=50",
        "--set",
        "learner.trunk=mlp",
        "--set",
        "learner.hidden=[32]",
        "--set",
        "telemetry.metrics_addr=127.0.0.1:0",
        "bench",
        "time-to-target",
        "--seeds",
        "3,4",
        "--minutes",
        "2",
        "--out",
        &folder_arg,
        "--json",
    ]);
    assert!(result.status.success(), "{}", stderr(&result));
    let report: serde_json::Value = serde_json::from_str(&stdout(&result)).expect("JSON");
    assert_eq!(report["trained"], "experiment ttg-left", "{report}");
    assert_eq!(report["reached"], 2, "{report}");
    let seeds = report["seeds"].as_array().expect("rows");
    assert_eq!(seeds.len(), 2, "{report}");
    for (row, seed) in seeds.iter().zip([3, 4]) {
        assert_eq!(row["seed"], seed, "{report}");
        assert_eq!(row["status"], "target", "{report}");
        let summary = folder.join(format!("seed-{seed}/summary.json"));
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&summary).expect("summary"))
                .expect("summary JSON");
        assert_eq!(
            row["wall_seconds_to_target"], summary["reached"]["evaluation"]["wall_seconds"],
            "{report}"
        );
        // The weights that confirmed it stay in `reached/`, with that
        // evaluation, whatever `best/` holds later.
        let reached = folder.join(format!("seed-{seed}/reached"));
        let kept: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(reached.join("evaluation.json")).expect("reached/"),
        )
        .expect("reached/evaluation.json");
        assert_eq!(kept, summary["reached"]["evaluation"], "{kept}");
        assert!(
            reached
                .join("weights.safetensors")
                .metadata()
                .expect("reached weights")
                .len()
                > 0
        );
        let config = std::fs::read_to_string(folder.join(format!("seed-{seed}/config.toml")))
            .expect("the run's config");
        assert!(config.contains(&format!("seed = {seed}")), "{config}");
    }
    assert!(report["median_wall_seconds"].as_f64().is_some(), "{report}");

    let bad = crossroads(&["bench", "time-to-target", "--minutes", "0"]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("--minutes"), "{}", stderr(&bad));

    // An experiment with no target (ttg-occluded) is refused before any
    // training, naming the key.
    let scratch = tempfile::tempdir().expect("temp dir");
    let runs = scratch.path().join("runs");
    let bad = crossroads(&[
        "--experiment",
        "ttg-occluded",
        "bench",
        "time-to-target",
        "--seeds",
        "1",
        "--minutes",
        "5",
        "--out",
        runs.to_str().expect("utf-8"),
    ]);
    assert!(!bad.status.success());
    let err = stderr(&bad);
    assert!(
        err.contains("experiment ttg-occluded sets no target")
            && err.contains("train.target_success"),
        "{err}"
    );
    assert!(!runs.join("seed-1").exists(), "it trained first");
}

/// `--experiment NAME train` runs in `runs/NAME`: a variant
/// (`creep-occluded+shield`) does not share its base experiment's folder,
/// and `--resume` reads that folder's config.toml, not another run's.
#[test]
fn an_experiment_trains_in_a_folder_of_its_own_name() {
    let scratch = tempfile::tempdir().expect("temp dir");
    let run = scratch.path().join("runs/creep-occluded+shield");
    std::fs::create_dir_all(&run).expect("mkdir");
    // A saved config that cannot start: a resume that reads it fails on it
    // before anything trains.
    std::fs::write(run.join("config.toml"), "[actor]\nenvs = 0\n").expect("write");
    let out = crate::crossroads()
        .command()
        .current_dir(scratch.path())
        // `--updates 1`: were the folder not read, a short run, not a long one.
        .args([
            "--experiment",
            "creep-occluded+shield",
            "train",
            "--resume",
            "--updates",
            "1",
        ])
        .output()
        .expect("run");
    assert!(!out.status.success(), "it trained");
    let err = stderr(&out);
    assert!(err.contains("actor.envs"), "{err}");
    assert!(
        !scratch.path().join("runs/creep-occluded").exists()
            && !scratch.path().join("runs/ttg-left").exists(),
        "another experiment's folder"
    );
}
