//! `crossroads train` end to end: the replay, the learner and an actor as
//! real processes over the real local transport (iceoryx2), then
//! `--resume`, and `eval --policy` on the best weights. The slow test
//! (`CROSSROADS_SLOW_TESTS=1`) trains long enough to measure an improvement
//! of the greedy evaluation over the untrained network; its quick twin runs
//! the same path on a budget too small to learn.

use std::path::Path;
use std::process::Output;

use crossroads_harness::train::{Evaluation, read_curve};
use crossroads_test_support::gates;

/// Warm-up and evaluations of a run long enough to learn.
const LEARNING: &[&str] = &[
    "replay.min_size_to_sample=500",
    "train.eval_every=200",
    "train.eval_trials=200",
    "train.confirm_trials=1000",
];

/// The same at a budget too small to learn anything.
const TINY: &[&str] = &[
    "replay.min_size_to_sample=100",
    "train.eval_every=10",
    "train.eval_trials=20",
    "train.confirm_trials=50",
];

/// `crossroads args` with info-level logs.
fn crossroads(args: &[&str]) -> Output {
    crate::crossroads()
        .command()
        .args(args)
        .env("RUST_LOG", "info")
        .output()
        .expect("run crossroads")
}

fn train(out: &Path, budget: &[&str], updates: &str, extra: &[&str]) -> Output {
    let out = out.to_str().expect("utf-8");
    let mut args = vec![
        "--set",
        "telemetry.metrics_addr=127.0.0.1:0",
        "--set",
        "learner.trunk=mlp",
        "--set",
        "learner.hidden=[64,64]",
    ];
    for set in budget {
        args.extend(["--set", set]);
    }
    args.extend([
        "train",
        "--scenario",
        "right",
        "--updates",
        updates,
        "--out",
        out,
    ]);
    args.extend_from_slice(extra);
    crossroads(&args)
}

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
        .expect("json")
}

/// What a finished run of at least `updates` leaves in its folder: the
/// curve from the untrained network on, the summary, logs, checkpoints and
/// `best/`, re-measured on `confirm_trials`, which `eval --policy` runs like
/// any policy. Returns the curve and the evaluation of `best/` (on 200
/// trials of Right).
fn check_finished_run(
    out: &Path,
    updates: u64,
    confirm_trials: u64,
) -> (Vec<Evaluation>, serde_json::Value) {
    let rows = read_curve(&out.join("curve.csv")).expect("curve");
    assert!(rows.len() >= 2, "{rows:?}");
    assert_eq!(rows[0].updates, 0, "the first evaluation is of the start");
    let s = summary(out);
    assert_eq!(s["status"], "finished", "{s}");
    assert!(s["updates"].as_u64().expect("updates") >= updates, "{s}");
    for file in [
        "config.toml",
        "curve.png",
        "best/weights.safetensors",
        "best/evaluation.json",
        "last/weights.safetensors",
        "logs/replay.log",
        "logs/learner.log",
        "logs/actor-0.log",
    ] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    let checkpoints: Vec<_> = std::fs::read_dir(out.join("checkpoints"))
        .expect("checkpoints")
        .filter_map(Result::ok)
        .collect();
    assert!(!checkpoints.is_empty(), "no checkpoint written");

    // The best weights evaluate like any policy.
    let best_dir = out.join("best");
    let o = crossroads(&[
        "eval",
        "--policy",
        best_dir.to_str().expect("utf-8"),
        "--scenario",
        "right",
        "--trials",
        "200",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let e: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert!(
        e["policy"]
            .as_str()
            .expect("name")
            .starts_with("dqn:best@v")
    );
    // best/ holds the re-measured evaluation (train.confirm_trials), not
    // the periodic one.
    let kept: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(best_dir.join("evaluation.json")).expect("best evaluation"),
    )
    .expect("json");
    assert_eq!(kept["trials"], confirm_trials, "{kept}");
    (rows, e)
}

/// The folder of a run that reached `before` updates (its curve `rows`)
/// needs --resume; with it the run continues to `after` updates.
fn check_resume(out: &Path, budget: &[&str], rows: &[Evaluation], before: u64, after: u64) {
    let after_arg = after.to_string();
    let o = train(out, budget, &after_arg, &[]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--resume"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let first = summary(out);
    let o = train(out, budget, &after_arg, &["--resume"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let second = summary(out);
    assert!(second["updates"].as_u64() >= Some(after), "{second}");
    assert!(
        second["wall_seconds"].as_f64() > first["wall_seconds"].as_f64(),
        "the clock continues: {first} -> {second}"
    );
    let resumed = read_curve(&out.join("curve.csv")).expect("curve");
    assert!(resumed.len() > rows.len());
    assert!(
        resumed[rows.len()].updates >= before,
        "the resumed learner starts from its checkpoint: {resumed:?}"
    );
}

#[test]
#[ignore = "slow: CROSSROADS_SLOW_TESTS=1 cargo test -- --include-ignored (make test runs it)"]
fn training_across_real_processes_beats_the_untrained_network() {
    if !gates::slow_tests_enabled(
        "train::training_across_real_processes_beats_the_untrained_network",
    ) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("run");
    let o = train(&out, LEARNING, "800", &[]);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{log}");

    let (rows, e) = check_finished_run(&out, 800, 1000);
    // A run of seconds may end before the actors' steps are first read.
    let s = summary(&out);
    assert!(s["env_steps"].as_u64().expect("steps") > 0, "{s}");
    assert!(rows.len() >= 3, "{rows:?}");
    let untrained = &rows[0];
    // An untrained network either waits for ever (0 % success, a whole
    // episode of step rewards) or goes at once (on Right about 90 %
    // success with 10 % collisions), depending on its initialization; the
    // score that picks the best weights (the mean undiscounted return) is
    // low either way, so training must lift it.
    let best = rows
        .iter()
        .map(|r| r.score())
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(
        best >= untrained.score() + 0.25 && best >= 0.5,
        "the greedy mean return went from {:.3} untrained to at best {best:.3}: {rows:?}",
        untrained.score()
    );
    // Judged by the same score as above: success alone can be lower than
    // an untrained network that goes at once and collides 10 % of the time.
    let score = e["mean_return"].as_f64().expect("mean return");
    assert!(score > untrained.score(), "{e} against {untrained:?}");

    check_resume(&out, LEARNING, &rows, 800, 1000);
}

/// The slow test's path on a budget too small to learn: the processes, the
/// evaluations, `best/` re-measured, checkpoints, `eval --policy` and
/// `--resume`, without the claim of a better policy.
#[test]
fn a_tiny_run_across_real_processes_writes_its_folder_and_resumes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("run");
    let o = train(&out, TINY, "30", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (rows, e) = check_finished_run(&out, 30, 50);
    assert_eq!(e["trials"], 200, "{e}");
    check_resume(&out, TINY, &rows, 30, 300);
    // Resumed on a full replay the learner updates at once: with a few
    // updates left it can finish before `train`'s first readiness probe
    // (every 200 ms); that is a finished run, not a failure.
    let rows = read_curve(&out.join("curve.csv")).expect("curve");
    let o = train(&out, TINY, "310", &["--resume"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    assert_eq!(s["status"], "finished", "{s}");
    assert!(s["updates"].as_u64() >= Some(310), "{s}");
    let resumed = read_curve(&out.join("curve.csv")).expect("curve");
    assert!(resumed.len() > rows.len(), "the last weights are evaluated");
}

#[test]
fn a_checkpoint_for_other_actions_is_refused_by_eval() {
    let dir = tempfile::tempdir().expect("temp dir");
    let spec = crossroads_model::NetworkSpec::new(
        crossroads_sim::observation_layout("sequential").expect("a view"),
        "sequential",
        crossroads_model::TrunkKind::Mlp,
        vec![8],
    )
    .expect("spec");
    let net = crossroads_model::QNetwork::new(spec, 1).expect("network");
    let file = dir.path().join("seq.safetensors");
    std::fs::write(&file, net.to_safetensors(3).expect("bytes")).expect("write");
    let args = [
        "eval",
        "--policy",
        file.to_str().expect("utf-8"),
        "--scenario",
        "left",
        "--trials",
        "10",
    ];
    // Asked to drive other actions than its own, it is refused, naming
    // what it reads.
    let o = crossroads(&[&args[..], &["--actions", "ttg"]].concat());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("sequential observations"), "{err}");
    // Without --actions it drives its own.
    let o = crossroads(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("(sequential actions)"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let o = crossroads(&["eval", "--policy", "no/such/checkpoint", "--trials", "10"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("checkpoint folder"), "{err}");
}

/// `actor.shield`: the actors act through the shield and the run's
/// evaluations are behind it too, so even an untrained network's curve
/// on Right shows no collision.
#[test]
fn a_tiny_run_with_the_shield_in_the_loop_evaluates_behind_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("run");
    let budget: Vec<&str> = TINY
        .iter()
        .copied()
        .chain(["actor.shield=default", "actor.veto_cost=0.05"])
        .collect();
    let o = train(&out, &budget, "30", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = read_curve(&out.join("curve.csv")).expect("curve");
    assert!(!rows.is_empty());
    assert!(
        rows.iter().all(|e| e.collision_rate == 0.0),
        "behind the shield: {:?}",
        rows.iter().map(|e| e.collision_rate).collect::<Vec<_>>()
    );
    let best = summary(&out)["best"].clone();
    assert_eq!(best["collision_rate"], 0.0, "{best}");
}
