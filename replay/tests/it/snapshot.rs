//! Snapshots: round trip, truncation and bit flips detected, fallback to
//! the last good snapshot, nothing corrupt ever replaces a good one.

use std::sync::Arc;
use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_replay::ReplayMetrics;
use crossroads_replay::snapshot::{self, SnapshotError, Snapshots};
use crossroads_replay::{Table, TableImage};

use crate::util::{insert, table};

async fn filled() -> Arc<Table> {
    let t = Arc::new(table(50, 0.6));
    for b in 0..7 {
        insert(&t, b * 10, 10, None).await;
    }
    t.update_priorities(&[45, 60, 3], &[2.5, 0.25, 9.0])
        .expect("valid");
    t.sample(8, 0.5, Duration::from_secs(1), &Shutdown::new())
        .await
        .expect("sample");
    t
}

fn snapshots(dir: &std::path::Path, keep: usize) -> Snapshots {
    Snapshots::new(dir.to_path_buf(), keep, ReplayMetrics::unregistered()).expect("dir")
}

fn files(dir: &std::path::Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("list")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[tokio::test]
async fn round_trip_restores_items_keys_priorities_and_counters() {
    let dir = tempfile::tempdir().expect("temp dir");
    let t = filled().await;
    let s = snapshots(dir.path(), 2);
    let written = s.write(std::slice::from_ref(&t)).expect("write");
    assert_eq!(written.items, 50);
    assert!(written.path.starts_with(dir.path()));

    let (path, images) = s.restore_latest().expect("read").expect("a snapshot");
    assert_eq!(path, written.path);
    assert_eq!(images.len(), 1);
    let (name, image) = &images[0];
    assert_eq!(name, "t");
    assert_eq!(image, &t.image());

    let restored = table(50, 0.6);
    assert_eq!(restored.restore(image).expect("fits"), 0);
    assert_eq!(restored.image(), t.image());
    let (a, b) = (restored.stats(), t.stats());
    assert_eq!(
        (
            a.info.size,
            a.next_key,
            a.info.inserts_total,
            a.info.samples_total,
            a.info.priority_updates_total,
            a.info.ignored_updates_total
        ),
        (
            b.info.size,
            b.next_key,
            b.info.inserts_total,
            b.info.samples_total,
            b.info.priority_updates_total,
            b.info.ignored_updates_total
        ),
    );
    // Keys go on where they stopped; evicted ones stay ignored.
    let u = restored
        .update_priorities(&[19, 20, 69], &[1.0, 1.0, 1.0])
        .expect("valid");
    assert_eq!((u.updated, u.ignored), (2, 1));
    insert(&restored, 500, 5, None).await;
    assert_eq!(restored.stats().next_key, 75);

    // A smaller table keeps the newest items.
    let small = table(20, 0.6);
    assert_eq!(small.restore(image).expect("fits"), 30);
    assert_eq!(
        small.image().items.rewards,
        image.items.rewards[30..].to_vec()
    );
}

#[tokio::test]
async fn empty_table_round_trips() {
    let bytes = snapshot::encode(&[("t".to_owned(), TableImage::default())]);
    let back = snapshot::decode(&bytes).expect("valid");
    assert_eq!(back, vec![("t".to_owned(), TableImage::default())]);
}

#[tokio::test]
async fn truncated_and_bit_flipped_snapshots_are_detected_at_every_byte() {
    let t = filled().await;
    let bytes = snapshot::encode(&[("t".to_owned(), t.image())]);
    for cut in (0..bytes.len()).step_by(7) {
        let err = snapshot::decode(&bytes[..cut]).expect_err("truncated");
        assert!(
            err.contains("truncated") || err.contains("checksum"),
            "cut at {cut}: {err}"
        );
    }
    for at in (0..bytes.len()).step_by(13) {
        let mut flipped = bytes.clone();
        flipped[at] ^= 0x10;
        assert!(
            snapshot::decode(&flipped).is_err(),
            "flip at {at} undetected"
        );
    }
}

#[tokio::test]
async fn a_corrupt_newest_snapshot_falls_back_to_the_last_good_one() {
    let dir = tempfile::tempdir().expect("temp dir");
    let t = filled().await;
    let s = snapshots(dir.path(), 2);
    let good = s.write(std::slice::from_ref(&t)).expect("first");
    let good_image = t.image();
    insert(&t, 900, 5, None).await;
    let newest = s.write(std::slice::from_ref(&t)).expect("second");
    assert_eq!(files(dir.path()).len(), 2);

    // Flip one bit in the middle of the newest.
    let mut bytes = std::fs::read(&newest.path).expect("read");
    let mid = bytes.len() / 2;
    bytes[mid] ^= 1;
    std::fs::write(&newest.path, &bytes).expect("write");
    match snapshot::read(&newest.path) {
        Err(SnapshotError::Corrupt { path, problem }) => {
            assert_eq!(path, newest.path);
            assert!(problem.contains("checksum"), "{problem}");
        }
        other => panic!("{other:?}"),
    }

    let (path, images) = s.restore_latest().expect("fallback").expect("a snapshot");
    assert_eq!(path, good.path, "the last good one");
    assert_eq!(images[0].1, good_image);
    let names = files(dir.path());
    assert!(
        names.iter().any(|n| n.ends_with(".crsnap.corrupt")),
        "kept aside: {names:?}"
    );

    // The next snapshot takes a new number; the corrupt file is not reused
    // or overwritten.
    let third = s.write(std::slice::from_ref(&t)).expect("third");
    assert_ne!(third.path, newest.path);
    assert!(
        files(dir.path())
            .iter()
            .any(|n| n.ends_with(".crsnap.corrupt"))
    );
}

#[tokio::test]
async fn only_corrupt_snapshots_stop_the_start_with_a_clear_error() {
    let dir = tempfile::tempdir().expect("temp dir");
    let t = filled().await;
    let s = snapshots(dir.path(), 1);
    let written = s.write(&[t]).expect("write");
    let len = std::fs::metadata(&written.path).expect("meta").len();
    let f = std::fs::OpenOptions::new()
        .write(true)
        .open(&written.path)
        .expect("open");
    f.set_len(len - 100).expect("truncate");
    drop(f);
    let err = s.restore_latest().expect_err("nothing valid");
    let message = err.to_string();
    assert!(
        matches!(err, SnapshotError::NoValidSnapshot { .. }),
        "{err:?}"
    );
    assert!(message.contains("truncated"), "{message}");
    assert!(
        message.contains(&written.path.display().to_string()),
        "{message}"
    );
    assert!(
        message.contains("replay.restore"),
        "says how to go on: {message}"
    );
}

#[tokio::test]
async fn keeps_only_the_newest_snapshots() {
    let dir = tempfile::tempdir().expect("temp dir");
    let t = filled().await;
    let s = snapshots(dir.path(), 2);
    let paths: Vec<_> = (0..4)
        .map(|_| s.write(std::slice::from_ref(&t)).expect("write").path)
        .collect();
    let names = files(dir.path());
    assert_eq!(names.len(), 2, "{names:?}");
    for p in &paths[2..] {
        assert!(p.exists());
    }
}

/// A snapshot whose checksums hold but whose items a valid batch could not
/// have stored, or whose insert count is below the items it holds (the
/// `snapshot` fuzz target's property: a restored table samples, and every
/// sample is a valid batch) is refused, and the table keeps what it held.
/// Before, `restore` checked only lengths, indices and priorities, and
/// such items reached the learner in samples.
#[tokio::test]
async fn an_image_no_valid_batch_could_make_is_refused_with_nothing_changed() {
    let t = filled().await;
    let good = t.image();
    type Spoil = fn(&mut TableImage);
    let spoil: [(&str, Spoil); 8] = [
        ("action", |i| i.items.actions[3] = 99),
        // Found by the fuzz target (CI): keys would overflow at the next
        // insert.
        ("next_key", |i| i.next_key = u64::MAX),
        // Found by the fuzz target: the limiter then never let a sample
        // through (fewer inserts than the minimum size).
        ("inserts", |i| i.inserts_total = 0),
        ("reward", |i| i.items.rewards[0] = f32::NAN),
        ("discount", |i| i.items.discounts[1] = 1.5),
        ("spec", |i| i.spec = None),
        ("layout", |i| {
            if let Some((layout, _)) = &mut i.spec {
                layout.rows = 0;
            }
        }),
        ("observation", |i| {
            // The first observation's first dictionary value (after the
            // one-byte channel and value counts) NaN; its length holds.
            assert!(i.observation_offsets[1] >= 6);
            i.observation_data[2..6].copy_from_slice(&f32::NAN.to_le_bytes());
        }),
    ];
    for (what, spoil) in spoil {
        let mut bad = good.clone();
        spoil(&mut bad);
        let restored = table(50, 0.6);
        insert(&restored, 900, 3, None).await;
        let before = restored.image();
        let err = restored.restore(&bad).expect_err(what);
        assert!(!err.field.is_empty(), "{what}: {err}");
        assert_eq!(restored.image(), before, "{what}: nothing changed");
    }
}

/// Counts restored from a file are counted on without overflow: a table
/// restored at the largest counts samples and takes priority updates
/// (found by the fuzz target in CI: the sample count overflowed and the
/// server panicked on the first sample).
#[tokio::test]
async fn counts_restored_at_their_largest_saturate_instead_of_overflowing() {
    let t = filled().await;
    let mut image = t.image();
    image.samples_total = u64::MAX - 1;
    image.inserts_total = u64::MAX;
    image.priority_updates_total = u64::MAX;
    image.ignored_updates_total = u64::MAX;
    let restored = table(50, 0.6);
    restored.restore(&image).expect("restores");
    let shutdown = Shutdown::new();
    let sample = restored
        .sample(8, 0.5, Duration::ZERO, &shutdown)
        .await
        .expect("samples");
    let keys = sample.keys.clone();
    restored
        .update_priorities(&keys, &vec![2.0; keys.len()])
        .expect("updates");
    let after = restored.image();
    assert_eq!(after.samples_total, u64::MAX);
    assert_eq!(after.priority_updates_total, u64::MAX);
}
