//! `crossroads sumo-check --quick --strict` as `make test` runs it: our
//! simulator against SUMO on left and challenge, under `sumo` and `human`
//! drivers (300 trials per cell, the TTC rule at 1.5, 2 and 3 s, never-go,
//! the empty-road drive). It fails
//! when a regime drifts: success, collision or time of a TTC cell outside
//! the 99 % interval of the difference, or a turn slower or faster than
//! SUMO's by more than 0.3 s.
//!
//! Needs SUMO in `.venv` (`scripts/setup-python.sh --sumo`), so it is
//! ignored unless asked for (`cargo test -- --include-ignored`, as `make
//! test` runs it); asked for without SUMO, it fails if
//! CROSSROADS_REQUIRE_SUMO=1 (as `make test` sets), and otherwise says so
//! and returns.

use std::path::Path;
use std::process::Command;

use crossroads_test_support::gates::{self, Need};

fn sumo_python() -> Option<std::path::PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let py = root.join(".venv/bin/python3");
    let ok = py.exists()
        && Command::new(&py)
            .args(["-c", "import libsumo, sumo"])
            .status()
            .is_ok_and(|s| s.success());
    ok.then_some(py)
}

#[test]
#[ignore = "needs SUMO in .venv (scripts/setup-python.sh --sumo): \
            CROSSROADS_REQUIRE_SUMO=1 cargo test -- --include-ignored"]
fn quick_sumo_check_finds_no_drift() {
    let Some(python) = sumo_python() else {
        gates::skip_unless_required(
            Need::Sumo,
            ".venv has no libsumo: run scripts/setup-python.sh --sumo",
        );
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = tempfile::tempdir().expect("temporary folder");
    let done = crate::crossroads()
        .command()
        .current_dir(root)
        .args(["sumo-check", "--quick", "--strict", "--out"])
        .arg(out.path())
        .arg("--python")
        .arg(&python)
        .output()
        .expect("run crossroads sumo-check");
    let stdout = String::from_utf8_lossy(&done.stdout);
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert!(
        done.status.success(),
        "sumo-check --quick --strict failed:\n{stdout}\n{stderr}"
    );
    assert!(stdout.contains("0 gated cells drift"), "{stdout}");
    // The report: both scenarios under both populations, their empty-road
    // drives, the figures.
    let readme = std::fs::read_to_string(out.path().join("README.md")).expect("README.md");
    for needle in [
        "## left (ttg actions)",
        "## challenge (ttg actions)",
        "## left+human (ttg actions)",
        "## challenge+human (ttg actions)",
        "Empty-road drive",
        "SUMO 1.28",
    ] {
        assert!(readme.contains(needle), "{needle} missing from\n{readme}");
    }
    let results: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out.path().join("results.json")).expect("results.json"),
    )
    .expect("results.json is JSON");
    let scenarios = results["scenarios"].as_array().expect("scenarios");
    // left, challenge and their empty-road drives, then both under human
    // drivers (no empty-road drive: without traffic the drivers do not
    // matter).
    assert_eq!(scenarios.len(), 6, "{scenarios:?}");
    for s in scenarios {
        for p in s["policies"].as_array().expect("policies") {
            assert_eq!(p["ours"]["trials"], p["sumo"]["trials"], "{p}");
        }
    }
    for f in ["ttc-curves.png", "success.png", "cells.csv"] {
        let len = std::fs::metadata(out.path().join(f)).map_or(0, |m| m.len());
        assert!(len > 100, "{f}: {len} bytes");
    }
}
