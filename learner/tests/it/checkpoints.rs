//! The checkpoint store: atomic writes, retention, id validation, and
//! resuming bit for bit.

use std::collections::BTreeMap;

use crossroads_config::TargetUpdate;
use crossroads_learner::bench::{SplitMix, synthetic_batch};
use crossroads_learner::checkpoint::{CheckpointStore, NewCheckpoint, StoreError, validate_id};
use crossroads_learner::optimizer::OptimizerConfig;
use crossroads_learner::{Trainer, TrainerConfig, TrainingBatch};
use crossroads_model::{NetworkSpec, QNetwork};
use tch::Tensor;

fn spec() -> NetworkSpec {
    crate::small_mlp()
}

fn config(optimizer: OptimizerConfig) -> TrainerConfig {
    TrainerConfig {
        spec: spec(),
        seed: 5,
        optimizer,
        max_grad_norm: 1.0,
        huber_delta: 1.0,
        target_update: TargetUpdate::Period,
        target_period: 4,
        target_tau: 0.01,
        priority_eps: 1e-6,
        go_labels: None,
    }
}

fn batches(n: usize) -> Vec<TrainingBatch> {
    let mut rng = SplitMix::new(3);
    (0..n)
        .map(|i| {
            let b = synthetic_batch(&spec(), 32, &mut rng);
            let w: Vec<f32> = (0..b.len()).map(|j| 0.5 + (j % 3) as f32 * 0.25).collect();
            TrainingBatch::from_batch(
                &b,
                &w,
                (0..b.len() as u64).map(|k| k + 100 * i as u64).collect(),
                &spec(),
            )
            .expect("test setup")
        })
        .collect()
}

fn bits(net: &QNetwork, x: &Tensor) -> Vec<u32> {
    let v: Vec<f32> =
        Vec::try_from(net.q_values(x).expect("test setup").flatten(0, -1)).expect("test setup");
    v.iter().map(|f| f.to_bits()).collect()
}

fn write(
    store: &CheckpointStore,
    t: &Trainer,
    version: u64,
    eval: &BTreeMap<String, f64>,
) -> String {
    let state = t.state(version).expect("test setup");
    store
        .write(&NewCheckpoint {
            state: &state,
            weights_version: version,
            scenario: "left",
            network: t.online().spec(),
            optimizer: t.config().optimizer.name(),
            eval_metrics: eval,
            eval_weights_version: version,
            config: "# test",
        })
        .expect("test setup")
        .manifest
        .id
}

#[test]
fn round_trip_gives_bit_identical_q_values_and_resume_is_exact() {
    for optimizer in [
        OptimizerConfig::Rmsprop {
            lr: 1e-3,
            decay: 0.95,
            eps: 0.01,
        },
        OptimizerConfig::Adam {
            lr: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-4,
        },
    ] {
        let dir = tempfile::tempdir().unwrap();
        let store = CheckpointStore::open(dir.path(), 3, "success_rate").unwrap();
        let data = batches(10);
        let x = data[0].obs.to_dense();

        let mut a = Trainer::new(config(optimizer)).unwrap();
        for b in &data[..6] {
            a.update(b).unwrap();
        }
        let id = write(&store, &a, 6, &BTreeMap::new());
        assert_eq!(id, "ckpt-000000000006");

        // The saved online network gives bit-identical Q-values.
        let loaded = store.load(&id).unwrap();
        let (online, version) = QNetwork::from_safetensors(&loaded.state.online).unwrap();
        assert_eq!(version, 6);
        assert_eq!(bits(&online, &x), bits(a.online(), &x));

        // A fresh trainer restored from it continues exactly as the
        // original: same networks, optimizer state and step.
        let mut b = Trainer::new(TrainerConfig {
            seed: 99,
            ..config(optimizer)
        })
        .unwrap();
        b.restore(loaded.state).unwrap();
        assert_eq!(b.step(), 6);
        for batch in &data[6..] {
            let sa = a.update(batch).unwrap();
            let sb = b.update(batch).unwrap();
            assert_eq!(sa.loss.to_bits(), sb.loss.to_bits(), "{optimizer:?}");
            assert_eq!(sa.priorities, sb.priorities);
        }
        assert_eq!(b.step(), 10);
        assert_eq!(bits(a.online(), &x), bits(b.online(), &x), "{optimizer:?}");
        assert_eq!(bits(a.target(), &x), bits(b.target(), &x), "{optimizer:?}");
    }
}

#[test]
fn keeps_the_newest_and_the_best_by_evaluation() {
    let dir = tempfile::tempdir().unwrap();
    let store = CheckpointStore::open(dir.path(), 2, "success_rate").unwrap();
    let data = batches(1);
    let mut t = Trainer::new(config(OptimizerConfig::Rmsprop {
        lr: 1e-3,
        decay: 0.95,
        eps: 0.01,
    }))
    .unwrap();
    let mut ids = Vec::new();
    for (i, rate) in [0.2, 0.9, 0.5, 0.4, 0.3].into_iter().enumerate() {
        t.update(&data[0]).unwrap();
        let eval = BTreeMap::from([("success_rate".to_owned(), rate)]);
        ids.push(write(&store, &t, i as u64 + 1, &eval));
    }
    let listed = store.list().unwrap();
    let names: Vec<(&str, bool)> = listed.iter().map(|e| (e.id(), e.best)).collect();
    assert_eq!(
        names,
        vec![
            (ids[4].as_str(), false),
            (ids[3].as_str(), false),
            (ids[1].as_str(), true)
        ]
    );
    // Saving twice at one step gets a distinct id.
    let again = write(&store, &t, 6, &BTreeMap::new());
    assert_eq!(again, format!("{}-2", ids[4]));
}

#[test]
fn ids_that_leave_the_folder_are_invalid_and_unknown_ones_not_found() {
    let dir = tempfile::tempdir().unwrap();
    let store = CheckpointStore::open(dir.path().join("ckpts"), 2, "success_rate").unwrap();
    for bad in [
        "../x",
        "..",
        ".",
        "a/b",
        "/etc",
        "ckpt\\1",
        ".tmp-ckpt",
        "",
        "a b",
    ] {
        let err = store.resolve(bad).unwrap_err();
        assert!(
            matches!(err, StoreError::InvalidId { .. }),
            "{bad:?}: {err}"
        );
        assert!(validate_id(bad).is_err());
    }
    assert!(matches!(
        store.resolve("ckpt-000000000001"),
        Err(StoreError::NotFound(_))
    ));
    assert!(matches!(
        store.delete("ckpt-000000000001"),
        Err(StoreError::NotFound(_))
    ));
    // A symlink inside the folder that points elsewhere is not followed.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(dir.path(), dir.path().join("ckpts/escape")).unwrap();
        let err = store.resolve("escape").unwrap_err();
        assert!(matches!(err, StoreError::InvalidId { .. }), "{err}");
    }
}

#[test]
fn interrupted_writes_are_cleaned_up_and_corruption_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let leftover = dir.path().join(".tmp-ckpt-000000000003-1234");
    std::fs::create_dir_all(&leftover).unwrap();
    std::fs::write(leftover.join("weights.safetensors"), b"partial").unwrap();
    let store = CheckpointStore::open(dir.path(), 2, "success_rate").unwrap();
    assert!(!leftover.exists());
    assert!(store.list().unwrap().is_empty());

    let t = Trainer::new(config(OptimizerConfig::Rmsprop {
        lr: 1e-3,
        decay: 0.95,
        eps: 0.01,
    }))
    .unwrap();
    let id = write(&store, &t, 1, &BTreeMap::new());
    let weights = dir.path().join(&id).join("weights.safetensors");
    let mut bytes = std::fs::read(&weights).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0xff;
    std::fs::write(&weights, bytes).unwrap();
    let err = store.load(&id).unwrap_err();
    assert!(matches!(err, StoreError::Corrupt { .. }), "{err}");
    assert!(err.to_string().contains("weights.safetensors"), "{err}");
}

#[test]
fn the_version_lease_round_trips_and_a_damaged_one_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let store = CheckpointStore::open(dir.path(), 2, "success_rate").unwrap();
    assert_eq!(store.version_lease().unwrap(), 0, "none leased yet");
    store.lease_versions(2048).unwrap();
    assert_eq!(store.version_lease().unwrap(), 2048);
    store.lease_versions(4096).unwrap();
    assert_eq!(store.version_lease().unwrap(), 4096);
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["versions.lease"], "no temporary file left");
    std::fs::write(dir.path().join("versions.lease"), "40\u{0}").unwrap();
    let err = store.version_lease().unwrap_err().to_string();
    assert!(
        err.contains("versions.lease") && err.contains("not a version"),
        "{err}"
    );
}
