//! `crossroads reproduce --quick`: the whole pipeline (training runs as
//! real processes, TTC sweeps, DQN evaluations, tables and figures) at a
//! smoke budget; then a second call reuses the finished runs. That takes
//! minutes (`CROSSROADS_SLOW_TESTS=1`); its quick twin runs Table II alone
//! (two runs) on a tiny budget.

use std::path::Path;
use std::process::Output;

use crossroads_test_support::gates;

fn reproduce(out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "--set",
        "telemetry.metrics_addr=127.0.0.1:0",
        "reproduce",
        "--quick",
        "--out",
        out.to_str().expect("utf-8"),
    ];
    args.extend_from_slice(extra);
    crate::crossroads().output(&args)
}

fn cell_trials(cell: &serde_json::Value) -> u64 {
    cell["trials"].as_u64().unwrap_or(0)
}

/// A cell of a policy (named starting with `inner`) behind the safety
/// shield: its trials, a policy name saying so, and veto counts that add
/// up.
fn assert_shielded(cell: &serde_json::Value, inner: &str, row: &serde_json::Value, trials: u64) {
    assert_eq!(cell_trials(cell), trials, "{row}");
    let policy = cell["policy"].as_str().unwrap_or_default();
    assert!(
        policy.starts_with(inner) && policy.ends_with("+shield"),
        "{row}"
    );
    let counts = &cell["shield"];
    let (goes, vetoes) = (
        counts["go_decisions"].as_u64().expect("go decisions"),
        counts["vetoes"].as_u64().expect("vetoes"),
    );
    assert!(vetoes <= goes, "{counts}");
    let kinds: u64 = ["crossing", "ahead", "behind"]
        .iter()
        .map(|k| counts[k].as_u64().expect("kind"))
        .sum();
    assert_eq!(kinds, vetoes, "every veto has a kind: {counts}");
}

#[test]
#[ignore = "slow: CROSSROADS_SLOW_TESTS=1 cargo test -- --include-ignored (make test runs it)"]
fn quick_reproduction_writes_every_table_and_figure_and_reuses_its_runs() {
    if !gates::slow_tests_enabled(
        "reproduce::quick_reproduction_writes_every_table_and_figure_and_reuses_its_runs",
    ) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("report");
    let o = reproduce(&out, &[]);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{log}");

    for file in [
        "README.md",
        "table1.csv",
        "table2.csv",
        "table3.csv",
        "training.csv",
        "results.json",
        "fig3.png",
        "curves.png",
        "configs/ttg-left.toml",
        "runs/ttg-left/best/weights.safetensors",
        "runs/creep-occluded/curve.png",
    ] {
        assert!(out.join(file).is_file(), "{file} missing; log:\n{log}");
    }
    for png in ["fig3.png", "curves.png"] {
        let bytes = std::fs::read(out.join(png)).expect("png");
        assert!(bytes.starts_with(b"\x89PNG"), "{png} is not a PNG");
    }

    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).expect("results"))
            .expect("json");
    assert_eq!(r["quick"], true);
    let t1 = r["table1"].as_array().expect("table1");
    assert_eq!(t1.len(), 5, "{t1:?}");
    for row in t1 {
        assert_eq!(cell_trials(&row["ttg"]), 300, "{row}");
        // The network trained behind the shield (ttg-<s>+shield), behind
        // it, with its counts.
        assert_shielded(&row["shielded"], "dqn:", row, 300);
        // The shield alone: `go` behind it.
        assert_shielded(&row["shield_alone"], "go", row, 300);
        // TTC's cell is the lowest threshold without collisions.
        assert_eq!(row["ttc"]["collision"].as_f64(), Some(0.0), "{row}");
        assert!(
            row["sequential"].is_null(),
            "--quick leaves DQN-Sequential out"
        );
    }
    let t2 = r["table2"].as_array().expect("table2");
    assert_eq!(t2.len(), 3);
    for row in t2 {
        for method in ["ttc_creep", "ttg", "creep"] {
            assert_eq!(cell_trials(&row[method]), 300, "{method}: {row}");
        }
        assert_shielded(&row["shielded"], "dqn:", row, 300);
        assert_shielded(&row["shield_alone"], "go", row, 300);
        assert_ladder(row, 300);
    }
    let t3 = r["table3"].as_array().expect("table3");
    assert_eq!(t3.len(), 5);
    for (i, row) in t3.iter().enumerate() {
        let row = row.as_array().expect("row");
        assert_eq!(row.len(), 5);
        // The diagonal is Table I's DQN-TTG cell.
        assert_eq!(row[i], t1[i]["ttg"], "diagonal {i}");
        assert!(row.iter().all(|c| cell_trials(c) == 300), "{row:?}");
    }
    let runs = r["runs"].as_array().expect("runs");
    assert_eq!(
        runs.len(),
        13,
        "5 TTG, 5 TTG behind the shield, creep, creep behind the shield and TTG on \
         occlusion: {runs:?}"
    );

    let md = std::fs::read_to_string(out.join("README.md")).expect("readme");
    assert!(md.contains("--quick smoke run"), "{md}");
    // Paper numbers sit beside ours: Left's DQN-TTG success is 99.99.
    assert!(md.contains("(99.99)"), "{md}");
    assert!(md.contains("![Figure 3](fig3.png)"), "{md}");
    assert!(md.contains("| DQN-TTG + shield |"), "{md}");
    assert!(md.contains("| DQN-Creep + shield |"), "{md}");
    assert!(
        md.contains("## How far from the limit under occlusion"),
        "{md}"
    );
    assert!(md.contains("| oracle |"), "{md}");
    assert!(md.contains("## The DQN behind the safety shield"), "{md}");
    assert!(md.contains("| Left, shield alone | "), "{md}");
    let csv = std::fs::read_to_string(out.join("table1.csv")).expect("csv");
    assert!(
        csv.lines()
            .any(|l| l.starts_with("left,dqn-ttg,success_%,") && l.ends_with(",99.99")),
        "{csv}"
    );
    assert!(
        csv.lines()
            .any(|l| l.starts_with("left,dqn-ttg+shield,success_%,") && l.ends_with(',')),
        "the shield's cells have no paper value: {csv}"
    );
    let training = std::fs::read_to_string(out.join("training.csv")).expect("csv");
    assert_eq!(training.lines().count(), 14, "{training}");
    // Safety across drivers: the networks too, bare and behind the shield.
    assert!(md.contains("(drivers/README.md)"), "{md}");
    let d: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("drivers/results.json")).expect("drivers results"),
    )
    .expect("json");
    let rows = d["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 50, "5 scenarios x (6 reactions + 4 shares)");
    for row in rows {
        assert_eq!(cell_trials(&row["ttg"]), 300, "{row}");
        assert_shielded(&row["shielded"], "dqn:", row, 300);
    }

    // Again, Table I only: every run is reused, nothing trains.
    let again = reproduce(&out, &["--only", "table1"]);
    let log2 = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{log2}");
    assert_eq!(
        log2.matches("reusing").count(),
        10,
        "5 TTG and 5 TTG behind the shield: {log2}"
    );
    assert!(!log2.contains("training into"), "{log2}");

    // A full reproduction into a quick report folder is refused.
    let o = crate::crossroads().output(&[
        "--set",
        "telemetry.metrics_addr=127.0.0.1:0",
        "reproduce",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("holds a quick reproduction"), "{err}");
}

/// The slow test's pipeline on Table II alone at a tiny budget: two
/// training runs as child processes, the TTC-with-creep sweeps, the DQN
/// cells bare and behind the shield, the report's files; then the runs
/// reused.
#[test]
fn a_tiny_reproduction_of_table2_trains_evaluates_reports_and_reuses() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("report");
    let tiny = [
        "--only",
        "table2",
        "--updates",
        "20",
        "--trials",
        "20",
        "--set",
        "replay.min_size_to_sample=100",
        "--set",
        "train.eval_every=10",
        "--set",
        "train.eval_trials=20",
        "--set",
        "train.confirm_trials=20",
    ];
    let o = reproduce(&out, &tiny);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{log}");
    for file in [
        "README.md",
        "table2.csv",
        "training.csv",
        "results.json",
        "configs/creep-occluded.toml",
        "runs/creep-occluded/best/weights.safetensors",
        "runs/ttg-occluded/curve.png",
    ] {
        assert!(out.join(file).is_file(), "{file} missing; log:\n{log}");
    }
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).expect("results"))
            .expect("json");
    assert_eq!(r["quick"], true);
    assert!(r["table1"].as_array().is_none_or(Vec::is_empty), "{r}");
    let t2 = r["table2"].as_array().expect("table2");
    assert_eq!(t2.len(), 3);
    for row in t2 {
        for method in ["ttc_creep", "ttg", "creep"] {
            assert_eq!(cell_trials(&row[method]), 20, "{method}: {row}");
        }
        assert_shielded(&row["shielded"], "dqn:", row, 20);
        assert_shielded(&row["shield_alone"], "go", row, 20);
        assert_ladder(row, 20);
    }
    let runs = r["runs"].as_array().expect("runs");
    assert_eq!(
        runs.len(),
        3,
        "creep, creep behind the shield and TTG on occlusion: {runs:?}"
    );
    let md = std::fs::read_to_string(out.join("README.md")).expect("readme");
    assert!(md.contains("--quick smoke run"), "{md}");
    assert!(md.contains("| DQN-Creep + shield |"), "{md}");
    assert!(
        md.contains("## How far from the limit under occlusion"),
        "{md}"
    );
    assert!(md.contains("| oracle |"), "{md}");

    let again = reproduce(&out, &tiny);
    let log2 = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{log2}");
    assert_eq!(log2.matches("reusing").count(), 3, "{log2}");
    assert!(!log2.contains("training into"), "{log2}");
}

/// `--only drivers` without networks: TTC tuned for human drivers and the
/// shield alone assuming them, every Table I scenario under each reaction
/// time and inattentive share, in drivers/; the paper's report untouched.
#[test]
fn safety_across_drivers_alone_writes_its_own_report() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("report");
    let o = crate::crossroads().output(&[
        "reproduce",
        "--baselines-only",
        "--only",
        "drivers",
        "--trials",
        "20",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{log}");
    for file in [
        "drivers/README.md",
        "drivers/drivers.csv",
        "drivers/results.json",
        "drivers/fig-reaction.png",
        "drivers/fig-inattentive.png",
    ] {
        assert!(out.join(file).is_file(), "{file} missing; log:\n{log}");
    }
    assert!(
        !out.join("README.md").exists(),
        "the paper's report is not rewritten"
    );
    let d: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("drivers/results.json")).expect("results"),
    )
    .expect("json");
    assert_eq!(d["sweeps"].as_array().map(Vec::len), Some(5));
    let rows = d["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 50, "5 scenarios x (6 reactions + 4 shares)");
    for row in rows {
        assert_shielded(&row["shield_alone"], "ttc:0", row, 20);
        assert!(row["ttg"].is_null(), "no networks: {row}");
        // TTC's threshold is the one tuned for human drivers, every row.
        let s = row["scenario"].as_str().expect("scenario");
        let tuned = d["sweeps"]
            .as_array()
            .and_then(|w| w.iter().find(|w| w["scenario"] == s))
            .map(|w| w["best"]["threshold"].clone());
        assert_eq!(Some(row["ttc_threshold"].clone()), tuned, "{row}");
        assert!(
            row["drivers"]
                .as_str()
                .is_some_and(|d| d.contains("reaction")),
            "{row}"
        );
    }
    let csv = std::fs::read_to_string(out.join("drivers/drivers.csv")).expect("csv");
    assert!(
        csv.lines()
            .any(|l| l.starts_with("left,reaction,1.5,shieldalone,")),
        "{csv}"
    );
    let md = std::fs::read_to_string(out.join("drivers/README.md")).expect("readme");
    assert!(
        md.contains("![collision rate against reaction, s](fig-reaction.png)"),
        "{md}"
    );
}

#[test]
fn reproduce_refuses_a_config_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cfg = dir.path().join("c.toml");
    std::fs::write(&cfg, "").expect("write");
    let o = crate::crossroads().output(&[
        "--config",
        cfg.to_str().expect("utf-8"),
        "reproduce",
        "--quick",
        "--out",
        dir.path().join("r").to_str().expect("utf-8"),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(
            "--config and --experiment (CROSSROADS_EXPERIMENT) apply to `crossroads train`"
        ),
        "{err}"
    );
}

#[test]
fn baselines_only_measures_ttc_without_training_or_weights() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("report");
    let o = crate::crossroads().output(&[
        "reproduce",
        "--baselines-only",
        "--only",
        "fig3",
        "--trials",
        "40",
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{log}");
    // Nothing trained: no run folder, no learning curves.
    let runs: Vec<_> = std::fs::read_dir(out.join("runs"))
        .expect("runs/")
        .collect();
    assert!(runs.is_empty(), "{runs:?}");
    assert!(!out.join("curves.png").exists());
    assert!(
        std::fs::read(out.join("fig3.png"))
            .expect("fig3")
            .starts_with(b"\x89PNG")
    );
    let results: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).expect("results"))
            .expect("JSON");
    assert_eq!(results["baselines_only"], true);
    let rows = results["table1"].as_array().expect("rows");
    assert_eq!(rows.len(), 4, "{rows:?}");
    for row in rows {
        // The TTC cell measured on every trial, the DQN cells left empty.
        assert_eq!(cell_trials(&row["ttc"]), 40, "{row}");
        assert!(row["ttg"].is_null() && row["sequential"].is_null(), "{row}");
    }
    let readme = std::fs::read_to_string(out.join("README.md")).expect("README");
    assert!(readme.contains("**Baselines only**"), "{readme}");
    // No claim about DQN cells that were never measured.
    assert!(!readme.contains("Where the DQNs fall short"), "{readme}");
}

/// Table II's ladder on a row: the shield alone with transparent walls
/// (with the shield's counts) and the oracle, on the row's trials; the
/// oracle succeeds at least as often as the shield alone.
fn assert_ladder(row: &serde_json::Value, trials: u64) {
    assert_shielded(&row["see_through"], "go", row, trials);
    let oracle = &row["oracle"];
    assert_eq!(cell_trials(oracle), trials, "{row}");
    assert!(
        oracle["policy"]
            .as_str()
            .is_some_and(|p| p.starts_with("oracle:")),
        "{row}"
    );
    let success = |c: &serde_json::Value| c["success"].as_f64().expect("success");
    assert!(success(oracle) >= success(&row["shield_alone"]), "{row}");
}
