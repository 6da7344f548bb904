//! VecEnv: reproducible by seed on any number of threads, auto-reset with
//! fresh seeds, episodes reported.

use std::sync::Arc;

use crossroads_sim::{ActionSet, EnvConfig, EnvStep, Scenario, VecEnv};
use crossroads_types::codec::ObservationEncoding;

/// Observations and results of `steps` steps with a fixed action pattern,
/// run on a pool of `threads`.
fn run(seed: u64, threads: usize, steps: usize) -> (Vec<f32>, Vec<EnvStep>, Vec<Vec<u8>>) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("pool");
    pool.install(|| {
        let scenario = Arc::new(Scenario::builtin("left").expect("scenario"));
        let mut envs = VecEnv::new(
            scenario,
            EnvConfig::for_actions(ActionSet::Ttg),
            6,
            seed,
            Some(ObservationEncoding::SparseF32),
        )
        .expect("envs");
        let mut obs = envs.observations().to_vec();
        let mut results = Vec::new();
        let mut encoded = Vec::new();
        for s in 0..steps {
            // Mostly waiting, sometimes going: episodes of every length.
            let actions: Vec<usize> = (0..envs.len())
                .map(|i| if (s + i) % 7 == 0 { 0 } else { 1 + (s + i) % 4 })
                .collect();
            results.extend_from_slice(envs.step(&actions).expect("step"));
            obs.extend_from_slice(envs.observations());
            for i in 0..envs.len() {
                encoded.push(envs.take_encoded(i));
            }
        }
        (obs, results, encoded)
    })
}

#[test]
fn the_same_seed_gives_the_same_run_on_any_number_of_threads() {
    let (o1, r1, e1) = run(11, 1, 60);
    let (o2, r2, e2) = run(11, 2, 60);
    assert_eq!(r1, r2);
    assert_eq!(o1, o2);
    assert_eq!(e1, e2);
    let ends: Vec<_> = r1.iter().filter_map(|r| r.episode).collect();
    assert!(ends.len() >= 6, "episodes end and restart: {}", ends.len());
    let mut seeds: Vec<u64> = ends.iter().map(|e| e.seed).collect();
    seeds.sort_unstable();
    seeds.dedup();
    assert_eq!(seeds.len(), ends.len(), "every episode has a fresh seed");
    assert!(r1.iter().all(|r| r.done == r.episode.is_some()));

    let (o3, r3, _) = run(12, 2, 60);
    assert!(o3 != o1 || r3 != r1, "another seed, another run");
}

#[test]
fn observations_are_contiguous_and_encoded() {
    let scenario = Arc::new(Scenario::builtin("left").expect("scenario"));
    let mut envs = VecEnv::new(
        scenario,
        EnvConfig::for_actions(ActionSet::Ttg),
        3,
        5,
        Some(ObservationEncoding::SparseF32),
    )
    .expect("envs");
    let len = envs.obs_len();
    assert_eq!(envs.observations().len(), 3 * len);
    assert_eq!(envs.layout().kind, "ttg");
    assert_eq!(envs.layout().check(), Ok(len));
    let row1 = envs.observations()[len..2 * len].to_vec();
    let bytes = envs.take_encoded(1);
    let mut decoded = vec![0.0; len];
    crossroads_types::codec::decode_into(ObservationEncoding::SparseF32, &bytes, &mut decoded)
        .expect("decodes");
    assert_eq!(decoded, row1);
    assert!(envs.step(&[0, 1]).is_err(), "one action per environment");
}

/// The dense rows are spread from the sparse lists, and both are what each
/// simulator writes itself, step after step (also where a caller reads
/// only one form for a while).
#[test]
fn dense_rows_and_sparse_lists_are_the_simulators_observations() {
    let scenario = Arc::new(Scenario::builtin("occluded").expect("scenario"));
    let mut envs = VecEnv::new(
        scenario,
        EnvConfig::for_actions(ActionSet::Creep),
        4,
        9,
        Some(ObservationEncoding::SparseF32),
    )
    .expect("envs");
    let len = envs.obs_len();
    let mut own = vec![0.0; len];
    for s in 0..80usize {
        let actions: Vec<usize> = (0..envs.len()).map(|i| (s + i) % 3).collect();
        envs.step(&actions).expect("step");
        if s % 3 == 1 {
            continue; // Neither form read: the next read must still be fresh.
        }
        let sparse = envs.sparse_observations().to_vec();
        let dense = envs.observations().to_vec();
        for i in 0..envs.len() {
            envs.env(i)
                .expect("environment")
                .write_observation(&mut own)
                .expect("observation");
            assert_eq!(
                &dense[i * len..(i + 1) * len],
                own.as_slice(),
                "step {s} env {i}"
            );
            let nonzero = crossroads_types::codec::nonzero_pairs(&own);
            assert_eq!(sparse[i], nonzero, "step {s} env {i}");
            let mut decoded = vec![0.0; len];
            crossroads_types::codec::decode_into(
                ObservationEncoding::SparseF32,
                &envs.take_encoded(i),
                &mut decoded,
            )
            .expect("decodes");
            assert_eq!(decoded, own, "step {s} env {i} encoded");
        }
    }
}
