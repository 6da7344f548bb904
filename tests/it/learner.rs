//! `crossroads learner` and `crossroads checkpoints` as an operator runs
//! them: real processes, a real replay server, loopback gRPC, SIGTERM, and
//! `crossroads bench learner`.

use std::path::Path;
use std::process::Output;

use crossroads_config::TransportConfig;
use crossroads_transport::grpc::ReplayClient;

fn checkpoints(learner: &str, args: &[&str]) -> Output {
    crate::crossroads()
        .command()
        .args(["checkpoints", "--learner", &format!("http://{learner}")])
        .args(args)
        .output()
        .expect("run crossroads checkpoints")
}

fn fill(replay: &str, config: &crossroads_config::Config) {
    let transport = TransportConfig {
        replay_endpoint: format!("http://{replay}"),
        ..TransportConfig::default()
    };
    let spec = crossroads_learner::TrainerConfig::from_config(&config.sim, &config.learner)
        .expect("valid")
        .spec;
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime")
        .block_on(async {
            let client = ReplayClient::new(&transport, "transitions")?;
            crossroads_learner::bench::fill_replay(&client, &spec, 1_000).await
        })
        .expect("fill the replay");
}

fn learner_args(replay: &str, dir: &Path, token_file: &Path) -> Vec<String> {
    vec![
        "--set".into(),
        "sim.action_set=sequential".into(),
        "--set".into(),
        "learner.hidden=[32]".into(),
        "--set".into(),
        "learner.batch_size=16".into(),
        "--set".into(),
        format!("transport.auth.token_file={}", token_file.display()),
        "learner".into(),
        "--listen".into(),
        "127.0.0.1:0".into(),
        "--replay".into(),
        format!("http://{replay}"),
        "--no-shm".into(),
        "--checkpoint-dir".into(),
        dir.display().to_string(),
    ]
}

#[test]
fn learner_and_checkpoints_commands_work_together() {
    let dir = tempfile::tempdir().expect("temp dir");
    let replay = crate::crossroads().spawn_role(&[
        "replay",
        "--listen",
        "127.0.0.1:0",
        "--no-shm",
        "--set",
        "replay.min_size_to_sample=1",
    ]);
    let replay_addr = replay.addr("replay server listening");
    let mut config = crossroads_config::Config::default();
    config.sim.action_set = "sequential".to_owned();
    crossroads_actor::resolve_observation(&mut config.sim).expect("a built-in pairing");
    config.learner.hidden = vec![32];
    fill(&replay_addr, &config);

    let ckpts = dir.path().join("ckpts");
    // The learner's token comes from a file (a mounted secret, say).
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, "tok3n\n").expect("token file");
    let args = learner_args(&replay_addr, &ckpts, &token_file);
    let learner = crate::crossroads().spawn_role(&args);
    let addr = learner.addr("learner listening");

    let out = checkpoints(&addr, &["list"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Without the token, save is refused with a clear error.
    let out = checkpoints(&addr, &["save"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("Unauthenticated") && err.contains("Bearer"),
        "{err}"
    );
    let out = checkpoints(&addr, &["--token", "tok3n", "save", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let saved: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let id = saved["id"].as_str().expect("id").to_owned();

    let out = checkpoints(&addr, &["list", "--json"]);
    let listed: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(listed[0]["id"], id.as_str());
    let text = checkpoints(&addr, &["list"]);
    assert!(String::from_utf8_lossy(&text.stdout).contains(&id));

    let pulled = dir.path().join("pulled");
    let out = checkpoints(
        &addr,
        &["pull", &id, "--out", pulled.to_str().expect("utf-8")],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for file in [
        "weights.safetensors",
        "target.safetensors",
        "optimizer.safetensors",
        "manifest.json",
    ] {
        assert_eq!(
            std::fs::read(pulled.join(&id).join(file)).expect("pulled file"),
            std::fs::read(ckpts.join(&id).join(file)).expect("learner's file"),
            "{file}"
        );
    }
    let out = checkpoints(
        &addr,
        &[
            "pull",
            "../../etc/passwd",
            "--out",
            pulled.to_str().expect("utf-8"),
        ],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("InvalidArgument"));
    let out = checkpoints(
        &addr,
        &["--token", "tok3n", "restore", "ckpt-000000000000-9"],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("NotFound"));
    let out = checkpoints(&addr, &["--token", "tok3n", "restore", &id]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("published as version"));

    // SIGTERM writes a last checkpoint.
    let before = std::fs::read_dir(&ckpts).expect("list").count();
    learner.terminate();
    let after = std::fs::read_dir(&ckpts).expect("list").count();
    assert!(after > before || after == 3, "{before} -> {after}");
    replay.terminate();
}

#[test]
fn learner_refuses_a_bad_learner_config_naming_the_key() {
    let out = crate::crossroads()
        .command()
        .args([
            "--set",
            "learner.optimizer=sgd",
            "--set",
            "learner.target_tau=0",
        ])
        .args(["learner", "--no-shm"])
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("learner.optimizer"), "{err}");
}

#[test]
fn bench_learner_prints_measured_figures() {
    let out = crate::crossroads()
        .command()
        .args([
            "--set",
            "learner.hidden=[32]",
            "--set",
            "sim.action_set=sequential",
        ])
        .args(["bench", "learner", "--rounds", "1", "--seconds", "0.2"])
        .args(["--fed-updates", "20", "--no-pytorch", "--json"])
        .output()
        .expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let rows = v["results"].as_array().expect("results");
    assert_eq!(rows.len(), 2);
    for (row, batch) in rows.iter().zip([64, 256]) {
        assert_eq!(row["batch_size"], batch);
        assert!(
            row["updates_per_sec"].as_f64().expect("rate") > 0.0,
            "{row}"
        );
        assert!(
            row["fed_updates_per_sec"].as_f64().expect("fed rate") > 0.0,
            "{row}"
        );
        let wait = row["fed_wait_fraction"].as_f64().expect("wait");
        assert!((0.0..=1.0).contains(&wait), "{row}");
    }
}

/// The action counts and absorbing *go*s `crossroads_types` knows by
/// name are the simulator's. (Observation layouts need no such check: the simulator
/// gives them, `crossroads_sim::observation_layout`.)
#[test]
fn action_set_sizes_match_the_simulator() {
    for set in crossroads_sim::ActionSet::ALL {
        assert_eq!(
            crossroads_model::num_actions_of(set.name()).expect("known set") as usize,
            set.num_actions()
        );
        assert_eq!(
            crossroads_model::absorbing_go_of(set.name()).expect("known set"),
            set.absorbing_go(),
            "{}",
            set.name()
        );
    }
}
