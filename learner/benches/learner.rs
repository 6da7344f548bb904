//! Criterion benchmarks of the learner: one update of the default network
//! (`[learner]` defaults: dueling MLP over the TTG grid, RMSProp) at batch
//! 64 and 256 on 2 libtorch threads, and decoding a sampled batch into
//! tensors. `crossroads bench learner` adds the gRPC-fed run and PyTorch.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use crossroads_config::{LearnerConfig, SimConfig};
use crossroads_learner::bench::{SplitMix, synthetic_batch};
use crossroads_learner::{Trainer, TrainerConfig, TrainingBatch};

fn updates(c: &mut Criterion) {
    tch::set_num_threads(2);
    let mut group = c.benchmark_group("learner_update");
    for batch in [64u32, 256] {
        let config = LearnerConfig {
            batch_size: batch,
            ..LearnerConfig::default()
        };
        let mut sim = SimConfig::default();
        sim.resolve_layout(crossroads_sim::observation_layout("ttg").expect("a view"))
            .expect("the default action set's view");
        let tc = TrainerConfig::from_config(&sim, &config).expect("default config is valid");
        let mut rng = SplitMix::new(1);
        let batches: Vec<TrainingBatch> = (0..4)
            .map(|_| {
                let b = synthetic_batch(&tc.spec, batch as usize, &mut rng);
                let n = b.len();
                TrainingBatch::from_batch(&b, &vec![1.0; n], (0..n as u64).collect(), &tc.spec)
                    .expect("synthetic batches fit")
            })
            .collect();
        let mut trainer = Trainer::new(tc.clone()).expect("default network builds");
        group.throughput(Throughput::Elements(1));
        let mut i = 0;
        group.bench_with_input(BenchmarkId::new("update", batch), &batch, |b, _| {
            b.iter(|| {
                i += 1;
                trainer.update(&batches[i % batches.len()]).expect("update")
            })
        });
        let raw = synthetic_batch(&tc.spec, batch as usize, &mut rng);
        let n = raw.len();
        group.bench_with_input(BenchmarkId::new("decode", batch), &batch, |b, _| {
            b.iter(|| {
                TrainingBatch::from_batch(&raw, &vec![1.0; n], (0..n as u64).collect(), &tc.spec)
                    .expect("decode")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, updates);
criterion_main!(benches);
