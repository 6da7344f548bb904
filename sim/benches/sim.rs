//! Throughput of the simulator per scenario: random TTG decisions (each
//! followed by writing the TTG observation, resets included) and single
//! simulation steps of a waiting ego.

use std::hint::black_box;
use std::sync::Arc;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use crossroads_sim::{ActionSet, Env, EnvConfig, PolicyRng, Scenario};
use rand::{RngExt, SeedableRng};

fn scenarios() -> Vec<Arc<Scenario>> {
    Scenario::builtin_names()
        .into_iter()
        .map(|n| Arc::new(Scenario::builtin(n).expect("built-in scenario")))
        .collect()
}

fn decisions(c: &mut Criterion) {
    let mut group = c.benchmark_group("ttg_decision_with_observation");
    group.throughput(Throughput::Elements(1));
    for sc in scenarios() {
        let mut env = Env::new(Arc::clone(&sc), EnvConfig::for_actions(ActionSet::Ttg));
        let mut obs = vec![0.0f32; env.obs_spec().len()];
        let mut rng = PolicyRng::seed_from_u64(1);
        let mut episode = 0;
        group.bench_function(sc.name(), |b| {
            b.iter(|| {
                let r = env.step(rng.random_range(0..5)).expect("valid action");
                if r.done {
                    episode += 1;
                    env.reset(episode);
                }
                env.write_observation(&mut obs).expect("right length");
                black_box(&obs);
            });
        });
    }
    group.finish();
}

fn steps(c: &mut Criterion) {
    let mut group = c.benchmark_group("sim_step");
    group.throughput(Throughput::Elements(1));
    for sc in scenarios() {
        let mut env = Env::new(Arc::clone(&sc), EnvConfig::for_actions(ActionSet::Ttg));
        let mut episode = 0;
        group.bench_function(sc.name(), |b| {
            b.iter(|| {
                // TTG action 1: wait one step.
                if env.step(1).expect("valid action").done {
                    episode += 1;
                    env.reset(episode);
                }
                black_box(env.traffic().len());
            });
        });
    }
    group.finish();
}

criterion_group!(benches, decisions, steps);
criterion_main!(benches);
