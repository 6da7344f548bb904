//! A weights file written by the learner loads in Python's safetensors with
//! the same tensor names, shapes and values; and the committed ttg-left
//! network, rebuilt in PyTorch by the Python package (`crossroads.torch`),
//! gives this crate's Q-values. Each needs Python (safetensors; the package
//! with its `torch` extra), so it is ignored unless asked for (`cargo test
//! -- --include-ignored`, as `make test` runs it after installing them);
//! asked for, it fails when they are missing if CROSSROADS_REQUIRE_PYTHON=1
//! (which `make test` sets), and otherwise says so and returns.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::process::Command;
use std::sync::Arc;

use crossroads_learner::checkpoint::{CheckpointStore, NewCheckpoint, WEIGHTS_FILE};
use crossroads_learner::{Trainer, TrainerConfig};
use crossroads_model::QNetwork;
use crossroads_sim::{ActionSet, Env, EnvConfig, Scenario};
use crossroads_test_support::gates::{self, Need};

const SCRIPT: &str = r#"
import json, sys
from safetensors import safe_open
from safetensors.numpy import load_file
tensors = load_file(sys.argv[1])
with safe_open(sys.argv[1], framework="numpy") as f:
    metadata = f.metadata()
print(json.dumps({
    "shapes": {k: list(v.shape) for k, v in tensors.items()},
    "dtypes": sorted({str(v.dtype) for v in tensors.values()}),
    "sums": {k: float(v.astype("float64").sum()) for k, v in tensors.items()},
    "metadata": metadata,
}))
"#;

fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("CROSSROADS_PYTHON") {
        return p.into();
    }
    let venv = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.venv/bin/python3");
    if venv.exists() {
        return venv;
    }
    "python3".into()
}

/// Whether `python` can import `module`; if not, skips the test (or fails
/// it when CROSSROADS_REQUIRE_PYTHON=1) naming what is missing.
fn python_has(python: &PathBuf, module: &str, what: &str) -> bool {
    let probe = Command::new(python)
        .args(["-c", &format!("import {module}")])
        .output();
    if matches!(&probe, Ok(o) if o.status.success()) {
        return true;
    }
    let why = match &probe {
        Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_owned(),
        Err(e) => e.to_string(),
    };
    gates::skip_unless_required(
        Need::Python,
        &format!("{what} is not available to {} ({why})", python.display()),
    );
    false
}

#[test]
#[ignore = "needs Python's safetensors (scripts/setup-python.sh): \
            CROSSROADS_REQUIRE_PYTHON=1 cargo test -- --include-ignored"]
fn learner_weights_load_in_python_safetensors() {
    let python = python();
    if !python_has(
        &python,
        "safetensors.numpy",
        "Python safetensors (scripts/setup-python.sh)",
    ) {
        return;
    }

    let config = crossroads_config::LearnerConfig {
        trunk: crossroads_types::TrunkKind::Conv,
        hidden: vec![8, 16, 64],
        ..Default::default()
    };
    let mut sim = crossroads_config::SimConfig::default();
    crate::set_observation(&mut sim, "ttg");
    let trainer = Trainer::new(TrainerConfig::from_config(&sim, &config).unwrap()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let store = CheckpointStore::open(dir.path(), 1, "success_rate").unwrap();
    let state = trainer.state(17).unwrap();
    let entry = store
        .write(&NewCheckpoint {
            state: &state,
            weights_version: 17,
            scenario: "left",
            network: trainer.online().spec(),
            optimizer: "rmsprop",
            eval_metrics: &BTreeMap::new(),
            eval_weights_version: 0,
            config: "",
        })
        .unwrap();
    let file = dir.path().join(entry.id()).join(WEIGHTS_FILE);

    let out = Command::new(&python)
        .args(["-c", SCRIPT])
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "python failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();

    let ours: BTreeMap<String, Vec<i64>> = trainer
        .online()
        .named_variables()
        .into_iter()
        .map(|(n, t)| (n, t.size()))
        .collect();
    let theirs: BTreeMap<String, Vec<i64>> =
        serde_json::from_value(report["shapes"].clone()).unwrap();
    assert_eq!(ours, theirs);
    assert_eq!(report["dtypes"], serde_json::json!(["float32"]));
    for (name, t) in trainer.online().named_variables() {
        let sum = t
            .to_kind(tch::Kind::Double)
            .sum(tch::Kind::Double)
            .double_value(&[]);
        let theirs = report["sums"][&name].as_f64().unwrap();
        assert!(
            (sum - theirs).abs() <= 1e-6 * (1.0 + sum.abs()),
            "{name}: {sum} vs {theirs}"
        );
    }
    assert_eq!(report["metadata"]["weights_version"], "17");
    assert_eq!(report["metadata"]["format"], "crossroads.qnetwork");
    let spec: crossroads_model::NetworkSpec =
        serde_json::from_str(report["metadata"]["spec"].as_str().unwrap()).unwrap();
    assert_eq!(&spec, trainer.online().spec());
}

/// Reads the batch and this crate's Q-values from the file in argv[1],
/// computes the Q-values of the network in argv[2] with `crossroads.torch`
/// and reports the largest difference.
const Q_SCRIPT: &str = r#"
import json, sys
import torch
from crossroads.torch import load_weights
from crossroads.weights import read_safetensors
with open(sys.argv[1], "rb") as f:
    _, batch = read_safetensors(f.read())
net = load_weights(sys.argv[2])
with torch.no_grad():
    q = net(torch.from_numpy(batch["observations"].copy()))
rust = torch.from_numpy(batch["q"].copy())
print(json.dumps({
    "rows": q.shape[0],
    "max_abs_diff": float((q - rust).abs().max()),
    "python_q": q.tolist(),
}))
"#;

/// The observations of a few episodes of the left turn (TTG view), as
/// actors see them, and one dense row of values in [0, 1) that reaches
/// every weight of the first layer.
fn ttg_observations(len: usize) -> Vec<f32> {
    let scenario = Arc::new(Scenario::load("left").expect("scenario"));
    let mut env = Env::new(scenario, EnvConfig::for_actions(ActionSet::Ttg));
    let mut obs = Vec::new();
    let mut row = vec![0.0; len];
    for seed in 0..6 {
        env.reset(seed);
        for _ in 0..3 {
            env.write_observation(&mut row).expect("observation");
            obs.extend_from_slice(&row);
            // Action 1 waits (the TTG set's shortest wait), so the
            // episode goes on.
            if env.step(1).expect("step").done {
                break;
            }
        }
    }
    obs.extend((0..len).map(|i| ((i * 2_654_435_761) % 1_000) as f32 / 1_000.0));
    obs
}

#[test]
#[ignore = "needs the Python package with its torch extra (pip install ./python[torch]): \
            CROSSROADS_REQUIRE_PYTHON=1 cargo test -- --include-ignored"]
fn committed_network_gives_the_same_q_values_in_pytorch() {
    let python = python();
    if !python_has(
        &python,
        "crossroads.torch",
        "the Python package with its torch extra (pip install './python[torch]')",
    ) {
        return;
    }
    let weights = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../reports/paper/runs/ttg-left/best/weights.safetensors");
    let bytes = std::fs::read(&weights).expect("committed weights");
    let (net, _) = QNetwork::from_safetensors(&bytes).expect("a network");
    let len = net.spec().input_len() as usize;
    let obs = ttg_observations(len);
    let rows = obs.len() / len;
    let q = net.infer(&obs, rows).expect("Q-values");

    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("batch.safetensors");
    let tensors = [
        (
            "observations".to_owned(),
            tch::Tensor::from_slice(&obs).reshape([rows as i64, len as i64]),
        ),
        (
            "q".to_owned(),
            tch::Tensor::from_slice(&q.q).reshape([rows as i64, q.num_actions as i64]),
        ),
    ];
    let encoded = crossroads_model::weights::encode(&tensors, &HashMap::new()).expect("encode");
    std::fs::write(&file, encoded).expect("write");

    let out = Command::new(&python)
        .args(["-c", Q_SCRIPT])
        .arg(&file)
        .arg(&weights)
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "python failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(report["rows"], rows);
    let diff = report["max_abs_diff"].as_f64().expect("a number");
    assert!(
        diff <= 1e-4,
        "PyTorch's Q-values differ from ours by up to {diff}: ours {:?}, PyTorch's {}",
        q.q,
        report["python_q"]
    );
}
