//! The invariants the crate graph states (ARCHITECTURE.md, "Code map"),
//! checked on the graph itself: `cargo tree` of each crate's normal
//! (non-dev) dependencies, so a new dependency that breaks one fails here.

use std::collections::BTreeSet;
use std::process::Command;

/// Every package `package` links in a normal build, transitively.
fn normal_dependencies(package: &str) -> BTreeSet<String> {
    let out = Command::new(env!("CARGO"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["tree", "--offline", "-e", "normal", "--prefix", "none"])
        .args(["--format", "{p}", "-p", package])
        .output()
        .expect("run cargo tree");
    assert!(
        out.status.success(),
        "cargo tree -p {package}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .skip(1)
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_owned)
        .collect()
}

#[test]
fn the_crate_graph_keeps_each_crate_to_its_part() {
    // (crate, what it must never link, why)
    let rules: [(&str, &[&str], &str); 11] = [
        (
            "crossroads-sim",
            &["tch", "torch-sys", "tokio", "tonic"],
            "the simulator knows nothing of learning or networking",
        ),
        (
            "crossroads-draw",
            &["tch", "torch-sys", "tokio", "tonic"],
            "pictures of scenes and curves need no network and no libtorch",
        ),
        (
            "crossroads-python",
            &["tch", "torch-sys", "tokio", "tonic"],
            "the Python wheel installs from PyPI and crates.io alone, without libtorch",
        ),
        (
            "crossroads-types",
            &["tch", "torch-sys", "tonic", "prost"],
            "domain types are plain data",
        ),
        (
            "crossroads-config",
            &[
                "tch",
                "torch-sys",
                "tonic",
                "prost",
                "crossroads-common",
                "crossroads-proto",
            ],
            "every role reads the schema; of ours it uses only the plain types",
        ),
        (
            "crossroads-common",
            &[
                "tch",
                "torch-sys",
                "tonic",
                "prost",
                "iceoryx2",
                "crossroads-proto",
            ],
            "run-time plumbing only",
        ),
        (
            "crossroads-transport",
            &["tch", "torch-sys"],
            "conversations carry bytes and domain types, never tensors",
        ),
        (
            "crossroads-replay",
            &["tch", "torch-sys", "crossroads-learner", "crossroads-sim"],
            "the replay stores transitions without a network or a simulator",
        ),
        (
            "crossroads-model",
            &["tokio", "tonic", "prost", "iceoryx2", "crossroads-sim"],
            "the network and its weights format, without networking",
        ),
        (
            "crossroads-actor",
            &["crossroads-learner"],
            "actors never see optimizer state",
        ),
        (
            "crossroads-learner",
            &["crossroads-sim", "crossroads-actor"],
            "the learner never steps a simulator",
        ),
    ];
    for (package, never, why) in rules {
        let deps = normal_dependencies(package);
        assert!(deps.len() > 2, "{package}: no dependencies read: {deps:?}");
        for forbidden in never {
            assert!(
                !deps.contains(*forbidden),
                "{package} links {forbidden}, but {why}"
            );
        }
    }
}

/// What the tests share is never shipped: the binary, which links every
/// library crate, links no test support.
#[test]
fn test_support_stays_a_dev_dependency() {
    let deps = normal_dependencies("crossroads");
    assert!(deps.len() > 2, "crossroads: no dependencies read: {deps:?}");
    assert!(
        !deps.contains("crossroads-test-support"),
        "crossroads-test-support is a normal dependency; it belongs in [dev-dependencies]"
    );
}
