//! Replay table benchmarks: inserts/s, samples/s, and bytes per stored
//! transition on synthetic TTG episodes. `cargo bench -p crossroads-replay`.
//! `REPLAY_BENCH_CAPACITY` sets the table size for the memory figure
//! (default 1,048,576).

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use crossroads_common::Shutdown;
use crossroads_replay::PreparedBatch;
use crossroads_replay::bench::{SyntheticEpisodes, bench_table, fill};

fn bytes_per_transition() {
    // `cargo test --all-targets` runs this file once as a smoke test (no
    // `--bench` argument): keep that quick.
    let benching = std::env::args().any(|a| a == "--bench");
    let capacity = std::env::var("REPLAY_BENCH_CAPACITY")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(if benching { 1 << 20 } else { 1 << 12 });
    let table = bench_table(capacity);
    let mut episodes = SyntheticEpisodes::new(1);
    fill(&table, &mut episodes, 64);
    let stats = table.stats();
    let per = stats.info.bytes_stored as f64 / stats.info.size as f64;
    println!(
        "replay/bytes_per_transition: {per:.1} bytes ({} transitions, {} distinct observations, {:.1} MiB; 2M transitions ~ {:.0} MiB)",
        stats.info.size,
        stats.observations,
        stats.info.bytes_stored as f64 / (1 << 20) as f64,
        per * 2e6 / (1 << 20) as f64,
    );
}

fn benches(c: &mut Criterion) {
    bytes_per_transition();

    let benching = std::env::args().any(|a| a == "--bench");
    let table = bench_table(if benching { 1 << 18 } else { 1 << 12 });
    let mut episodes = SyntheticEpisodes::new(2);
    fill(&table, &mut episodes, 64);

    let mut group = c.benchmark_group("replay");
    group.measurement_time(Duration::from_secs(5));
    group.throughput(Throughput::Elements(64));
    group.bench_function("insert_batch64_with_encoding", |b| {
        b.iter_batched(
            || episodes.batch(64),
            |batch| {
                let p = PreparedBatch::try_from(batch).expect("valid batch");
                black_box(table.insert_now(&p).expect("fits"))
            },
            criterion::BatchSize::SmallInput,
        )
    });
    let prepared: Vec<_> = (0..64)
        .map(|_| PreparedBatch::try_from(episodes.batch(64)).expect("valid"))
        .collect();
    let mut i = 0;
    group.bench_function("insert_batch64_prepared", |b| {
        b.iter(|| {
            i = (i + 1) % prepared.len();
            black_box(table.insert_now(&prepared[i]).expect("fits"))
        })
    });

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let shutdown = Shutdown::new();
    group.throughput(Throughput::Elements(256));
    group.bench_function("sample_batch256", |b| {
        b.iter(|| {
            black_box(
                runtime
                    .block_on(table.sample(256, 0.4, Duration::from_secs(1), &shutdown))
                    .expect("sample"),
            )
        })
    });
    group.throughput(Throughput::Elements(256));
    let keys: Vec<u64> = {
        let s = runtime
            .block_on(table.sample(256, 0.4, Duration::from_secs(1), &shutdown))
            .expect("sample");
        s.keys
    };
    let priorities: Vec<f32> = (0..256).map(|i| 0.1 + i as f32 * 0.01).collect();
    group.bench_function("update_priorities256", |b| {
        b.iter(|| black_box(table.update_priorities(&keys, &priorities).expect("valid")))
    });
    group.finish();
}

criterion_group!(replay, benches);
criterion_main!(replay);
