//! A weights file written by the learner loads in Python's safetensors with
//! the same tensor names, shapes and values. Needs Python's safetensors, so
//! it is ignored unless asked for (`cargo test -- --include-ignored`, as
//! `make test` runs it after installing safetensors); asked for, it fails
//! when safetensors is missing if CROSSROADS_REQUIRE_PYTHON=1 (which `make
//! test` sets), and otherwise says so and returns.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;

use crossroads_learner::checkpoint::{CheckpointStore, NewCheckpoint, WEIGHTS_FILE};
use crossroads_learner::{Trainer, TrainerConfig};
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

#[test]
#[ignore = "needs Python's safetensors (scripts/setup-python.sh): \
            CROSSROADS_REQUIRE_PYTHON=1 cargo test -- --include-ignored"]
fn learner_weights_load_in_python_safetensors() {
    let python = python();
    let probe = Command::new(&python)
        .args(["-c", "import safetensors.numpy"])
        .output();
    let available = matches!(&probe, Ok(o) if o.status.success());
    if !available {
        let why = match &probe {
            Ok(o) => String::from_utf8_lossy(&o.stderr).trim().to_owned(),
            Err(e) => e.to_string(),
        };
        gates::skip_unless_required(
            Need::Python,
            &format!(
                "Python safetensors is not available to {} ({why}); run scripts/setup-python.sh",
                python.display()
            ),
        );
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
