//! The seed corpora: a handful of valid inputs per target, each made by
//! the encoder the target's decoder reads (and one or two near misses),
//! written by `cargo run --example seed_corpus` into `corpus/<target>/`.

use crossroads_config::{Config, WeightNormalization};
use crossroads_replay::rate_limiter::RateLimiterConfig;
use crossroads_replay::snapshot;
use crossroads_replay::{PreparedBatch, Table, TableConfig, TableMetrics};
use crossroads_transport::{convert, shm, weights_shm, wire};
use crossroads_types::checkpoint::{
    FileEntry, MANIFEST_FORMAT, MANIFEST_VERSION, Manifest, OPTIMIZER_FILE, TARGET_FILE,
    WEIGHTS_FILE,
};
use crossroads_types::codec::{self, ObservationEncoding};
use crossroads_types::{
    NetworkSpec, ObservationLayout, Sample, Transition, TransitionBatch, TrunkKind, ValidBatch,
    Weights,
};
use prost::Message;

use crate::{
    batch_header_to_bytes, join_sections, optimizer_file, small_spec, weights_file,
    weights_header_to_bytes,
};

/// One seed: target, file name, bytes.
pub type Seed = (&'static str, String, Vec<u8>);

fn batch(encoding: ObservationEncoding, layout: ObservationLayout, transitions: u32) -> ValidBatch {
    let len = layout.check().expect("a valid layout") as u32;
    let mut b = TransitionBatch::new(layout, 3, encoding);
    let observations: Vec<u32> = (0..3)
        .map(|k| {
            let values: Vec<f32> = (0..len)
                .map(|i| {
                    if (i + k) % 3 == 0 {
                        i as f32 * 0.5 - 1.0
                    } else {
                        0.0
                    }
                })
                .collect();
            b.push_observation(&values)
        })
        .collect();
    for i in 0..transitions {
        b.push(Transition {
            observation: observations[i as usize % 3],
            action: i % 3,
            reward: i as f32 - 1.5,
            discount: if i == transitions - 1 { 0.0 } else { 0.9 },
            priority: 0.5 + i as f32,
            next_observation: observations[(i as usize + 1) % 3],
        });
    }
    ValidBatch::new(b).expect("a valid batch")
}

/// A small valid dense batch (also what the snapshot target's tables hold
/// before a restore).
pub fn dense_batch() -> ValidBatch {
    batch(
        ObservationEncoding::DenseF32,
        ObservationLayout::new("toy", 1, 2, 3, 0),
        4,
    )
}

fn sparse_batch() -> ValidBatch {
    batch(
        ObservationEncoding::SparseF32,
        ObservationLayout::new("toy", 4, 5, 3, 2),
        5,
    )
}

fn wire_batch() -> Vec<Seed> {
    let encode = |b: &ValidBatch| wire::batch_to_wire(b.clone().into_inner()).encode_to_vec();
    let mut nan = wire::batch_to_wire(dense_batch().into_inner());
    nan.rewards[1] = f32::NAN;
    let sample = wire::sample_to_wire(Sample {
        keys: vec![3, 4, 5, 6, 7],
        weights: vec![1.0, 0.5, 0.25, 1.0, 0.75],
        batch: sparse_batch().into_inner(),
    });
    vec![
        ("wire_batch", "dense".into(), encode(&dense_batch())),
        ("wire_batch", "sparse".into(), encode(&sparse_batch())),
        ("wire_batch", "nan-reward".into(), nan.encode_to_vec()),
        ("wire_batch", "sample".into(), sample.encode_to_vec()),
    ]
}

fn specs() -> Vec<NetworkSpec> {
    vec![
        small_spec(),
        NetworkSpec::new(
            ObservationLayout::new("large", 5, 18, 26, 4),
            "ttg",
            TrunkKind::Conv,
            vec![8, 16, 32],
        )
        .expect("spec"),
        NetworkSpec::new(
            ObservationLayout::new("large-occluded", 6, 18, 26, 4),
            "sequential",
            TrunkKind::Mlp,
            vec![64, 64],
        )
        .expect("spec"),
    ]
}

fn weights(version: u64) -> Weights {
    Weights::from_safetensors(
        weights_file(&small_spec(), version),
        10 * version,
        1_700_000,
    )
    .expect("valid weights")
}

fn wire_weights() -> Vec<Seed> {
    let with_pick = |pick: u8, bytes: Vec<u8>| [vec![pick], bytes].concat();
    let mut seeds: Vec<Seed> = specs()
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let bytes = with_pick(1, convert::spec_to_wire(s).encode_to_vec());
            ("wire_weights", format!("spec-{i}"), bytes)
        })
        .collect();
    let w = convert::weights_to_wire(&weights(3));
    seeds.push((
        "wire_weights",
        "weights".into(),
        with_pick(0, w.encode_to_vec()),
    ));
    seeds
}

fn observation_codec() -> Vec<Seed> {
    let values = [0.0, 1.5, 0.0, -2.0, 0.0, 0.25, 0.0, 0.0];
    [
        ObservationEncoding::DenseF32,
        ObservationEncoding::SparseF32,
    ]
    .into_iter()
    .enumerate()
    .map(|(pick, e)| {
        let mut bytes = vec![pick as u8];
        bytes.extend_from_slice(&(values.len() as u16).to_le_bytes());
        codec::encode(e, &values, &mut bytes);
        ("observation_codec", format!("{e:?}"), bytes)
    })
    .collect()
}

fn shm_batch_frame() -> Vec<Seed> {
    [("dense", dense_batch()), ("sparse", sparse_batch())]
        .into_iter()
        .map(|(name, b)| {
            let (header, len) =
                shm::BatchFrameHeader::for_batch("transitions", 9, &b).expect("fits a frame");
            let mut payload = vec![0; len];
            shm::write_frame(&b, &mut payload);
            let bytes = [vec![0], batch_header_to_bytes(&header), payload].concat();
            ("shm_batch_frame", name.to_owned(), bytes)
        })
        .collect()
}

fn shm_weights_frame() -> Vec<Seed> {
    let w = weights(5);
    let header = weights_shm::weights_frame_header(&w);
    let frame = [weights_header_to_bytes(&header), w.safetensors.clone()].concat();
    let mut stale = weights_shm::weights_frame_header(&w);
    stale.weights_version = 4;
    let mismatch = [weights_header_to_bytes(&stale), w.safetensors].concat();
    vec![
        ("shm_weights_frame", "weights".into(), frame),
        ("shm_weights_frame", "version-mismatch".into(), mismatch),
    ]
}

fn safetensors() -> Vec<Seed> {
    vec![
        (
            "safetensors",
            "weights".into(),
            weights_file(&specs()[1], 2),
        ),
        (
            "safetensors",
            "optimizer".into(),
            optimizer_file("rmsprop", 12),
        ),
    ]
}

fn checkpoint() -> Vec<Seed> {
    let spec = small_spec();
    let online = weights_file(&spec, 4);
    let target = weights_file(&spec, 3);
    let optimizer = optimizer_file("adam", 40);
    let manifest = Manifest {
        format: MANIFEST_FORMAT.to_owned(),
        format_version: MANIFEST_VERSION,
        id: "ckpt-000000000001".to_owned(),
        update_step: 40,
        weights_version: 4,
        created_unix_ms: 1_700_000_000_000,
        scenario: "left".to_owned(),
        network: spec,
        optimizer: "adam".to_owned(),
        eval_metrics: [("success_rate".to_owned(), 0.75)].into_iter().collect(),
        eval_weights_version: 3,
        config: "[sim]\nscenario = \"left\"\n".to_owned(),
        files: [
            (WEIGHTS_FILE, &online),
            (TARGET_FILE, &target),
            (OPTIMIZER_FILE, &optimizer),
        ]
        .into_iter()
        .map(|(name, bytes)| (name.to_owned(), FileEntry::of(bytes)))
        .collect(),
    };
    let json = serde_json::to_vec_pretty(&manifest).expect("a manifest prints");
    let input = |flags: u8| {
        let sections = join_sections(&[&json, &online, &target, &optimizer]);
        [vec![flags], sections].concat()
    };
    vec![
        ("checkpoint", "checked".into(), input(0)),
        ("checkpoint", "fixed-up".into(), input(1)),
    ]
}

/// An empty table `t` of `capacity` items that samples as soon as it
/// holds one (no rate limit): the table the snapshot and write-ahead-log
/// targets and their seeds restore into.
pub fn small_table(capacity: usize) -> Table {
    let config = TableConfig {
        name: "t".to_owned(),
        capacity,
        alpha: 0.6,
        min_priority: 1e-6,
        normalization: WeightNormalization::Table,
        seed: 1,
        limiter: RateLimiterConfig {
            min_size_to_sample: 1,
            samples_per_insert: 0.0,
            tolerance: 0.0,
            ramp: None,
        },
    };
    Table::new(config, TableMetrics::unregistered("t"))
}

fn snapshot() -> Vec<Seed> {
    let table = small_table(8);
    for b in [dense_batch(), dense_batch()] {
        table
            .insert_now(&PreparedBatch::new(b))
            .expect("a valid batch");
    }
    let file = snapshot::encode(&[("t".to_owned(), table.image())]);
    let body = file[32..].to_vec();
    let empty = snapshot::encode(&[("t".to_owned(), Default::default())]);
    vec![
        ("snapshot", "file".into(), [vec![0], file].concat()),
        ("snapshot", "body".into(), [vec![1], body].concat()),
        ("snapshot", "empty-table".into(), [vec![0], empty].concat()),
    ]
}

fn wal() -> Vec<Seed> {
    let images: Vec<_> = [dense_batch(), sparse_batch()]
        .into_iter()
        .enumerate()
        .map(|(i, b)| PreparedBatch::new(b).to_image(10 * i as u64))
        .collect();
    let mut segment = crossroads_replay::wal::segment_header().to_vec();
    for image in &images {
        crossroads_replay::wal::encode_record(&mut segment, "t", image);
    }
    let mut record = Vec::new();
    crossroads_replay::wal::encode_record(&mut record, "t", &images[0]);
    let torn = segment[..segment.len() - 5].to_vec();
    vec![
        ("wal", "segment".into(), [vec![0], segment].concat()),
        ("wal", "torn-tail".into(), [vec![0], torn].concat()),
        (
            "wal",
            "record-body".into(),
            [vec![1], record[8..].to_vec()].concat(),
        ),
    ]
}

fn compact_observation() -> Vec<Seed> {
    let values: Vec<f32> = (0..24)
        .map(|i| if i % 5 == 0 { 0.25 * i as f32 } else { 0.0 })
        .collect();
    let mut dense = Vec::new();
    codec::encode_dense(&values, &mut dense);
    let mut compact_bytes = Vec::new();
    crossroads_replay::compact::from_wire(
        ObservationEncoding::DenseF32,
        &dense,
        values.len(),
        3,
        &mut Vec::new(),
        &mut Vec::new(),
        &mut compact_bytes,
    );
    let decode = [
        vec![0],
        (values.len() as u16).to_le_bytes().to_vec(),
        compact_bytes,
    ]
    .concat();
    let encode = [vec![1, 3], dense].concat();
    vec![
        ("compact_observation", "decode".into(), decode),
        ("compact_observation", "encode".into(), encode),
    ]
}

fn config_toml() -> Vec<Seed> {
    let small = "[sim]\nscenario = \"left\"\n\n[replay]\ncapacity = 5000\nalpha = 0.6\n\n\
                 [learner]\nbatch_size = 32\nhidden = [64, 64]\n";
    let sets = "--set\nreplay.capacity=1000\nlearner.gamma=0.95\nactor.envs=2\n";
    vec![
        ("config_toml", "small".into(), small.as_bytes().to_vec()),
        (
            "config_toml",
            "defaults".into(),
            Config::default().to_toml().into_bytes(),
        ),
        ("config_toml", "sets".into(), sets.as_bytes().to_vec()),
    ]
}

/// Every seed of every target.
pub fn all() -> Vec<Seed> {
    [
        wire_batch(),
        wire_weights(),
        observation_codec(),
        shm_batch_frame(),
        shm_weights_frame(),
        safetensors(),
        checkpoint(),
        snapshot(),
        compact_observation(),
        config_toml(),
        wal(),
    ]
    .concat()
}
