//! Table semantics: proportional sampling, importance weights, FIFO
//! eviction, ignored updates, shared observations, concurrency.

use std::sync::Arc;
use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_config::WeightNormalization;
use crossroads_replay::{PreparedBatch, Table, TableError, TableMetrics};
use crossroads_types::{RejectReason, Sample, TransitionBatch, ValidBatch};

use crate::util::{self, insert, obs, prepared, table};

async fn sample(t: &Table, n: usize, beta: f64) -> Sample<TransitionBatch> {
    t.sample(n, beta, Duration::from_secs(5), &Shutdown::new())
        .await
        .expect("sample")
}

/// Chi-square statistic of observed counts against expected probabilities.
fn chi_square(counts: &[u64], probabilities: &[f64]) -> f64 {
    let n: u64 = counts.iter().sum();
    counts
        .iter()
        .zip(probabilities)
        .map(|(c, p)| {
            let e = p * n as f64;
            (*c as f64 - e).powi(2) / e
        })
        .sum()
}

#[tokio::test]
async fn sampling_frequencies_match_priorities() {
    // 10 items with priorities 1..10; 9 degrees of freedom: the 0.1%
    // critical value is 27.88.
    let priorities: Vec<f32> = (1..=10).map(|p| p as f32).collect();
    for alpha in [1.0, 0.5, 0.0] {
        let t = table(10, alpha);
        insert(&t, 0, 10, Some(&priorities)).await;
        let mut counts = vec![0u64; 10];
        for _ in 0..100 {
            let s = sample(&t, 1000, 0.0).await;
            for k in s.keys {
                counts[k as usize] += 1;
            }
        }
        let leaves: Vec<f64> = priorities
            .iter()
            .map(|p| f64::from(*p).powf(alpha))
            .collect();
        let total: f64 = leaves.iter().sum();
        let expected: Vec<f64> = leaves.iter().map(|l| l / total).collect();
        let chi2 = chi_square(&counts, &expected);
        assert!(
            chi2 < 27.88,
            "alpha {alpha}: chi2 {chi2}, counts {counts:?}"
        );
        // And the heaviest item is drawn about as often as it should be.
        let share = counts[9] as f64 / 100_000.0;
        assert!(
            (share - expected[9]).abs() < 0.01,
            "alpha {alpha}: {share} vs {}",
            expected[9]
        );
    }
}

#[tokio::test]
async fn importance_weights_match_hand_computed_values() {
    // Priorities 1, 2, 4, 8; alpha 0.5 gives leaves 1, sqrt 2, 2, 2 sqrt 2,
    // total 7.2426. With N = 4 and beta 0.5:
    //   w_i = (N P_i)^-0.5 = (4 leaf_i / 7.2426)^-0.5
    //       = 1.3456, 1.1315, 0.9515, 0.8001
    // normalized by the table's largest (item 0): 1, 0.8409, 0.7071, 0.5946.
    let expected = [
        1.0f32,
        0.840_896_4,
        std::f32::consts::FRAC_1_SQRT_2,
        0.594_603_6,
    ];
    let t = table(4, 0.5);
    insert(&t, 0, 4, Some(&[1.0, 2.0, 4.0, 8.0])).await;
    let s = sample(&t, 400, 0.5).await;
    let mut seen = [false; 4];
    for (k, w) in s.keys.iter().zip(&s.weights) {
        let k = *k as usize;
        seen[k] = true;
        assert!(
            (w - expected[k]).abs() < 1e-6,
            "key {k}: {w} vs {}",
            expected[k]
        );
    }
    assert!(seen.iter().all(|s| *s), "every item drawn in 400 samples");
    assert_eq!(s.batch.columns.priorities.len(), 400);

    // beta 0: no correction.
    let s = sample(&t, 50, 0.0).await;
    assert!(s.weights.iter().all(|w| *w == 1.0));

    // Normalized by the batch: the batch's lowest priority gets 1 and the
    // others (leaf_min / leaf_i)^beta.
    let mut config = util::table_config(4, 0.5);
    config.normalization = WeightNormalization::Batch;
    let t = Table::new(config, TableMetrics::unregistered("t"));
    insert(&t, 0, 4, Some(&[1.0, 2.0, 4.0, 8.0])).await;
    for _ in 0..20 {
        let s = sample(&t, 3, 1.0).await;
        let min_leaf = s
            .batch
            .columns
            .priorities
            .iter()
            .map(|p| f64::from(*p).sqrt())
            .fold(f64::INFINITY, f64::min);
        for (p, w) in s.batch.columns.priorities.iter().zip(&s.weights) {
            let want = (min_leaf / f64::from(*p).sqrt()) as f32;
            assert!((w - want).abs() < 1e-6, "{w} vs {want}");
        }
        assert!(s.weights.contains(&1.0));
    }
}

#[tokio::test]
async fn eviction_is_first_in_first_out_and_updates_for_evicted_keys_are_ignored() {
    let t = table(5, 1.0);
    for tag in 0..8 {
        insert(&t, tag, 1, None).await;
    }
    let stats = t.stats();
    assert_eq!(
        (stats.info.size, stats.info.inserts_total, stats.next_key),
        (5, 8, 8)
    );
    let image = t.image();
    assert_eq!(
        image.items.rewards,
        vec![3.0, 4.0, 5.0, 6.0, 7.0],
        "oldest evicted first"
    );
    let s = sample(&t, 200, 0.0).await;
    assert!(s.keys.iter().all(|k| (3..8).contains(k)), "{:?}", s.keys);

    let done = t
        .update_priorities(&[0, 2, 5, 7, 99], &[1.0, 1.0, 5.0, 0.0, 1.0])
        .expect("valid");
    assert_eq!((done.updated, done.ignored), (2, 3));
    let stats = t.stats();
    assert_eq!(
        (
            stats.info.priority_updates_total,
            stats.info.ignored_updates_total
        ),
        (2, 3)
    );
    assert_eq!(t.image().items.priorities, vec![1.0, 1.0, 5.0, 1.0, 0.0]);

    // A zero priority is floored, not unsampleable forever; but key 7 (now
    // at the floor) is drawn far less than key 5.
    let s = sample(&t, 2000, 0.0).await;
    let n7 = s.keys.iter().filter(|k| **k == 7).count();
    let n5 = s.keys.iter().filter(|k| **k == 5).count();
    assert!(n7 < 5 && n5 > 900, "key 7 drawn {n7}, key 5 drawn {n5}");
}

#[tokio::test]
async fn sampled_items_are_what_was_inserted() {
    let t = table(100, 0.6);
    insert(&t, 0, 30, None).await;
    insert(&t, 30, 30, None).await;
    let s = sample(&t, 64, 0.4).await;
    s.batch.validate().expect("a valid batch");
    let mut values = vec![0.0; util::SPEC_LEN];
    for i in 0..s.batch.len() {
        let tag = s.batch.columns.rewards[i] as u32;
        assert_eq!(s.keys[i], u64::from(tag), "key = insertion order");
        assert_eq!(s.batch.columns.actions[i], tag % 4);
        assert_eq!(s.batch.columns.discounts[i], 0.9);
        let tr = s.batch.transition(i).expect("in range");
        s.batch
            .observations
            .decode_into(tr.observation as usize, &mut values)
            .expect("decodes");
        assert_eq!(values, obs(tag));
        s.batch
            .observations
            .decode_into(tr.next_observation as usize, &mut values)
            .expect("decodes");
        assert_eq!(values, obs(tag + 1));
    }
    // Observations appear once in the answer's pool.
    assert!(s.batch.observations.len() <= 2 * s.batch.len());
}

#[tokio::test]
async fn observations_are_stored_once_and_freed_with_their_items() {
    let t = table(40, 1.0);
    insert(&t, 0, 10, None).await;
    assert_eq!(t.stats().observations, 11, "10 transitions share 11 states");
    // The next batch starts where the last ended: its first state is the
    // previous batch's last next state, found and shared.
    insert(&t, 10, 10, None).await;
    assert_eq!(t.stats().observations, 21);
    let bytes_half = t.stats().info.bytes_stored;
    for round in 0..20u32 {
        insert(&t, 1000 + round * 10, 10, None).await;
    }
    let stats = t.stats();
    assert_eq!(stats.info.size, 40);
    assert!(
        stats.observations <= 44,
        "{} observations for 40 items",
        stats.observations
    );
    assert!(
        stats.info.bytes_stored < bytes_half * 3,
        "memory follows the size: {} vs {bytes_half}",
        stats.info.bytes_stored
    );
}

#[tokio::test]
async fn a_batch_of_another_spec_is_rejected_and_changes_nothing() {
    let t = table(10, 1.0);
    insert(&t, 0, 3, None).await;
    let before = t.image();
    let mut other = util::batch(0, 2, None);
    other.layout.kind = "sequential".to_owned();
    let err = t
        .insert(
            &PreparedBatch::new(ValidBatch::new(other).expect("valid alone")),
            Duration::from_secs(1),
            &Shutdown::new(),
        )
        .await
        .expect_err("spec differs");
    match err {
        TableError::Invalid(e) => {
            assert_eq!((e.reason, e.field.as_str()), (RejectReason::Spec, "layout"));
        }
        other => panic!("{other:?}"),
    }
    let err = t
        .update_priorities(&[0, 1], &[1.0, f32::NAN])
        .expect_err("NaN");
    assert!(err.to_string().contains("priorities[1]"), "{err}");
    let err = t.update_priorities(&[0], &[-1.0]).expect_err("negative");
    assert!(err.to_string().contains("priorities[0]"), "{err}");
    assert_eq!(t.image(), before);
}

#[tokio::test]
async fn a_reserved_batch_is_sampled_only_once_stored_and_a_dropped_reservation_leaves_nothing() {
    let t = Arc::new(table(10, 1.0));
    let before = t.image();
    let first = prepared(0, 3, None);
    let reservation = t.reserve_now(&first).expect("room");
    // Reserved, not stored (its log record on the way): nothing to sample.
    let none = t
        .sample(1, 0.0, Duration::from_millis(20), &Shutdown::new())
        .await;
    assert!(
        matches!(none, Err(TableError::Timeout { .. })),
        "{:?}",
        none.as_ref().err()
    );
    assert_eq!(t.stats().info.size, 0);
    // Its spec is the table's meanwhile: a batch of another is refused.
    let mut other = util::batch(0, 2, None);
    other.layout.kind = "sequential".to_owned();
    let other = PreparedBatch::new(ValidBatch::new(other).expect("valid alone"));
    assert!(matches!(t.reserve_now(&other), Err(TableError::Invalid(_))));
    // Dropped unstored (its record failed): the table is as it was, spec
    // included, so the other spec goes in now.
    drop(reservation);
    assert_eq!(t.image(), before);
    let stored = t
        .reserve_now(&other)
        .expect("the spec is free again")
        .store(&other);
    assert_eq!((stored.first_key, stored.inserted, stored.size), (0, 2, 2));
    let s = sample(&t, 2, 0.0).await;
    assert_eq!(s.keys.len(), 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn actors_insert_while_the_learner_samples_and_updates() {
    let t = Arc::new(table(500, 0.6));
    let shutdown = Shutdown::new();
    let mut actors = Vec::new();
    for a in 0..4u32 {
        let t = t.clone();
        let shutdown = shutdown.clone();
        actors.push(tokio::spawn(async move {
            for b in 0..100u32 {
                let p = prepared(a * 100_000 + b * 16, 16, None);
                t.insert(&p, Duration::from_secs(10), &shutdown)
                    .await
                    .expect("insert");
                tokio::task::yield_now().await;
            }
        }));
    }
    let learner = {
        let t = t.clone();
        let shutdown = shutdown.clone();
        tokio::spawn(async move {
            let mut steps = 0;
            let mut ignored = 0;
            while steps < 200 {
                let s = t
                    .sample(32, 0.4, Duration::from_secs(10), &shutdown)
                    .await
                    .expect("sample");
                s.batch.validate().expect("valid sample");
                tokio::task::yield_now().await;
                let priorities: Vec<f32> = s.keys.iter().map(|k| (k % 7) as f32 + 0.5).collect();
                ignored += t
                    .update_priorities(&s.keys, &priorities)
                    .expect("update")
                    .ignored;
                steps += 1;
            }
            ignored
        })
    };
    for a in actors {
        a.await.expect("actor");
    }
    let ignored = learner.await.expect("learner");
    let stats = t.stats();
    assert_eq!(stats.info.inserts_total, 4 * 100 * 16);
    assert_eq!(stats.info.size, 500);
    assert_eq!(stats.info.samples_total, 200 * 32);
    assert_eq!(stats.info.ignored_updates_total, u64::from(ignored));
    assert_eq!(
        stats.info.priority_updates_total + stats.info.ignored_updates_total,
        200 * 32
    );
}
