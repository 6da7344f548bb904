//! The README's quick start, as a newcomer runs it: every command of its
//! one-machine block run as written, from a fresh folder (the training on a
//! small budget, set through the environment); every command of its
//! container block named with the line of `tests/it/deploy.rs` that runs
//! it.

use std::path::{Path, PathBuf};

use crossroads_test_support::gates;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The command lines of the `n`-th ```sh block under "## Quick start",
/// comments and blank lines dropped.
fn quick_start_block(n: usize) -> Vec<String> {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README.md");
    let section = readme
        .split("\n## Quick start\n")
        .nth(1)
        .expect("README.md has a ## Quick start section");
    let section = section.split("\n## ").next().unwrap_or(section);
    let block = section
        .split("```sh\n")
        .nth(n + 1)
        .and_then(|b| b.split("```").next())
        .unwrap_or_else(|| panic!("the quick start has no sh block {n}"));
    block
        .lines()
        .map(|l| l.split(" #").next().unwrap_or(l).trim().to_owned())
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .collect()
}

/// What `make run` runs: the `crossroads` command of the Makefile's `run`
/// recipe, without `$(RUN_ARGS)`.
fn make_run() -> Vec<String> {
    let makefile = std::fs::read_to_string(root().join("Makefile")).expect("Makefile");
    let recipe = makefile
        .split("\nrun:")
        .nth(1)
        .and_then(|r| r.lines().nth(1))
        .expect("the Makefile has a run target with a recipe");
    let (_, args) = recipe
        .split_once("crossroads ")
        .expect("make run runs crossroads");
    args.split_whitespace()
        .filter(|a| !a.starts_with("$("))
        .map(str::to_owned)
        .collect()
}

/// A small budget for `make run`'s training, through the environment so
/// the command itself stays as written: a small MLP, 30 updates, short
/// evaluations, metrics on free ports.
const SMALL: &[(&str, &str)] = &[
    ("CROSSROADS_TELEMETRY__METRICS_ADDR", "127.0.0.1:0"),
    ("CROSSROADS_LEARNER__TRUNK", "mlp"),
    ("CROSSROADS_LEARNER__HIDDEN", "[64, 64]"),
    ("CROSSROADS_LEARNER__MAX_UPDATES", "30"),
    ("CROSSROADS_REPLAY__MIN_SIZE_TO_SAMPLE", "100"),
    ("CROSSROADS_TRAIN__EVAL_EVERY", "10"),
    ("CROSSROADS_TRAIN__EVAL_TRIALS", "20"),
    ("CROSSROADS_TRAIN__CONFIRM_TRIALS", "50"),
];

/// The slow test's first claim, in plain `cargo test` too.
#[test]
fn the_quick_start_begins_with_make_run() {
    let lines = quick_start_block(0);
    assert!(
        lines.first().is_some_and(|l| l == "make run"),
        "the quick start begins with make run: {lines:?}"
    );
}

#[test]
#[ignore = "slow: CROSSROADS_SLOW_TESTS=1 cargo test -- --include-ignored (make test runs it)"]
fn the_quick_start_runs_as_written_from_a_fresh_folder() {
    let lines = quick_start_block(0);
    assert!(
        lines.first().is_some_and(|l| l == "make run"),
        "the quick start begins with make run: {lines:?}"
    );
    if !gates::slow_tests_enabled("readme::the_quick_start_runs_as_written_from_a_fresh_folder") {
        return;
    }
    // A fresh folder, with the repository's committed report beside it
    // (what a clone has) for the line that evaluates its network.
    let dir = tempfile::tempdir().expect("temp dir");
    std::os::unix::fs::symlink(root().join("reports"), dir.path().join("reports"))
        .expect("link reports/");
    for line in &lines {
        let (args, small): (Vec<String>, bool) = if line == "make run" {
            (make_run(), true)
        } else if line.starts_with("export PATH=") {
            continue;
        } else {
            let args = line
                .strip_prefix("crossroads ")
                .unwrap_or_else(|| panic!("not a crossroads command: {line}"));
            (args.split_whitespace().map(str::to_owned).collect(), false)
        };
        let mut cmd = crate::crossroads().command();
        cmd.args(&args).current_dir(dir.path());
        if small {
            cmd.envs(SMALL.iter().copied());
        }
        let started = std::time::Instant::now();
        let out = cmd.output().expect("run crossroads");
        eprintln!(
            "readme: `{line}` took {:.1} s",
            started.elapsed().as_secs_f64()
        );
        assert!(
            out.status.success(),
            "`{line}` failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    for made in [
        "runs/ttg-left/best",
        "runs/ttg-left/curve.png",
        "left.gif",
        "left.png",
        "quick-report/README.md",
    ] {
        assert!(
            dir.path().join(made).exists(),
            "the quick start made no {made}"
        );
    }
}

/// Each line of the container block, and the code of
/// `tests/it/deploy.rs` that runs it (with a test project's name, files
/// and a free learner port), whitespace aside.
const CONTAINER_LINES: &[(&str, &str)] = &[
    (
        "deploy/build-image.sh",
        "repo().join(\"deploy/build-image.sh\")",
    ),
    (
        "ACTORS=2 docker compose up -d --scale actor=2",
        "project.command(&[\"up\", \"-d\", \"--scale\", \"actor=2\"])",
    ),
    (
        // The monitoring profile's public Prometheus and Grafana images
        // cannot be pulled where the tests run: the test renders the
        // profile (`config`) and runs Debian's Prometheus with
        // deploy/prometheus.yml against the containers instead.
        "docker compose --profile monitoring up -d",
        "[\"--profile\", \"monitoring\", \"config\"]",
    ),
    (
        "crossroads checkpoints list --learner http://127.0.0.1:50052",
        "\"checkpoints\", \"--learner\", &learner_url, \"list\"",
    ),
    (
        "crossroads checkpoints pull <ID> --out pulled/ --learner http://127.0.0.1:50052",
        "\"pull\", &id, \"--out\"",
    ),
    (
        "crossroads eval --policy pulled/<ID> --scenario left",
        ".args([\"eval\", \"--scenario\", \"left\", \"--trials\", \"50\", \"--policy\"])",
    ),
    (
        "docker compose down -v",
        "project.command(&[\"down\", \"-v\", \"--timeout\", \"20\"])",
    ),
];

#[test]
fn every_container_command_of_the_quick_start_is_run_by_the_deployment_test() {
    let lines = quick_start_block(1);
    let expected: Vec<&str> = CONTAINER_LINES.iter().map(|(l, _)| *l).collect();
    assert_eq!(
        lines, expected,
        "the README's container block changed: update CONTAINER_LINES and the deployment test"
    );
    let deploy: PathBuf = root().join("tests/it/deploy.rs");
    // Compared without whitespace, so rustfmt's line breaks do not matter.
    let squeeze = |s: &str| s.split_whitespace().collect::<String>();
    let code = squeeze(&std::fs::read_to_string(&deploy).expect("deploy.rs"));
    for (line, snippet) in CONTAINER_LINES {
        assert!(
            code.contains(&squeeze(snippet)),
            "{} no longer runs `{line}` (looked for {snippet})",
            deploy.display()
        );
    }
}
