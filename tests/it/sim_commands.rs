//! `crossroads eval`, `tune-ttc` and `bench sim` as a user runs them.

use std::process::Command;

fn crossroads(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_crossroads"))
        .args(args)
        .env_remove("CROSSROADS_CONFIG")
        .output()
        .expect("run crossroads");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn eval_json(threads: &str) -> serde_json::Value {
    let set = format!("runtime.compute_threads={threads}");
    let (ok, stdout, stderr) = crossroads(&[
        "--set",
        &set,
        "eval",
        "--policy",
        "ttc:3",
        "--scenario",
        "left",
        "--trials",
        "300",
        "--seed",
        "11",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    serde_json::from_str(&stdout).expect("one JSON object")
}

#[test]
fn eval_json_has_the_documented_fields_and_ignores_thread_count() {
    let one = eval_json("1");
    for field in [
        "scenario",
        "policy",
        "trials",
        "success_rate",
        "collision_rate",
        "timeout_rate",
        "mean_time_s",
        "mean_brake_s",
    ] {
        assert!(one.get(field).is_some(), "{field} missing: {one}");
    }
    assert_eq!(one["scenario"], "left");
    assert_eq!(one["policy"], "ttc:3");
    assert_eq!(one["trials"], 300);
    let rates: f64 = ["success_rate", "collision_rate", "timeout_rate"]
        .iter()
        .map(|f| one[f].as_f64().expect("rate"))
        .sum();
    assert!(
        (rates - 1.0).abs() < 1e-9,
        "rates are fractions summing to 1: {one}"
    );

    let mut two = eval_json("2");
    let mut one = one;
    for v in [&mut one, &mut two] {
        v.as_object_mut().expect("object").remove("wall_seconds");
    }
    assert_eq!(one, two, "same seed, same result on 1 and 2 threads");
}

#[test]
fn eval_rejects_bad_input_with_a_clear_error() {
    let (ok, _, stderr) = crossroads(&["eval", "--policy", "ttc:-2"]);
    assert!(!ok);
    assert!(stderr.contains("ttc:-2"), "{stderr}");
    let (ok, _, stderr) = crossroads(&["eval", "--policy", "random", "--scenario", "roundabout"]);
    assert!(!ok);
    assert!(stderr.contains("roundabout"), "{stderr}");
    let (ok, _, stderr) = crossroads(&["eval", "--policy", "random", "--actions", "fly"]);
    assert!(!ok);
    assert!(stderr.contains("fly"), "{stderr}");
}

#[test]
fn tune_ttc_writes_csv_and_png() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().to_str().expect("utf-8");
    let (ok, stdout, stderr) = crossroads(&[
        "tune-ttc",
        "--scenario",
        "right",
        "--trials",
        "100",
        "--thresholds",
        "0.5,2,6",
        "--out",
        out,
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("threshold"), "{stdout}");
    let csv = std::fs::read_to_string(dir.path().join("tune-ttc-right.csv")).expect("csv");
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows[0][0], "threshold_s");
    assert_eq!(rows.len(), 4, "header and three thresholds: {csv}");
    let thresholds: Vec<f64> = rows[1..]
        .iter()
        .map(|r| r[0].parse().expect("number"))
        .collect();
    assert_eq!(thresholds, vec![0.5, 2.0, 6.0]);
    let png = std::fs::read(dir.path().join("tune-ttc-right.png")).expect("png");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "a real PNG");
}

#[test]
fn bench_sim_prints_measured_figures() {
    let (ok, stdout, stderr) = crossroads(&["bench", "sim", "--seconds", "0.1", "--json"]);
    assert!(ok, "{stderr}");
    let figures: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    let figures = figures.as_array().expect("one entry per scenario");
    assert!(figures.iter().any(|f| f["scenario"] == "left"));
    for f in figures {
        assert!(
            f["decisions_per_s"].as_f64().is_some_and(|d| d > 0.0),
            "{f}"
        );
        assert!(f["steps_per_s"].as_f64().is_some_and(|d| d > 0.0), "{f}");
    }
}
