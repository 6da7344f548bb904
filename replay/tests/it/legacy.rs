//! Replay files of the builds before the observation layout was carried: a
//! snapshot or a log segment of format version 1, whose tables stated their
//! observations as a kind and a flat shape, still restore (as a legacy
//! layout of that kind and length); the table then takes a batch of that
//! kind and length in the layout actors send now, and holds that layout
//! from then on.

use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_replay::{PreparedBatch, TableImage, snapshot, wal};
use crossroads_types::{ObservationLayout, ValidBatch};

use crate::util::{SPEC_LEN, batch, insert, layout, prepared, table};

/// One table as format version 1 wrote it, from this build's bytes of it
/// (`body` starts at its name): the layout after the name (spec flag 2,
/// the kind, four u32) becomes spec flag 1, the kind, rank 1 and the flat
/// length.
fn version_1_table(body: &[u8], name: &str, layout: &ObservationLayout) -> Vec<u8> {
    let flag = 4 + name.len();
    assert_eq!(body[flag], 2, "this build writes the layout");
    let kind_end = flag + 1 + 4 + layout.kind.len();
    let mut old = body[..flag].to_vec();
    old.push(1);
    old.extend_from_slice(&body[flag + 1..kind_end]);
    old.extend_from_slice(&1u32.to_le_bytes());
    old.extend_from_slice(&(layout.len() as u32).to_le_bytes());
    old.extend_from_slice(&body[kind_end + 16..]);
    old
}

/// A version 1 snapshot of one table.
fn version_1_snapshot(name: &str, image: &TableImage) -> Vec<u8> {
    let (layout, _) = image.spec.clone().expect("a layout");
    let file = snapshot::encode(&[(name.to_owned(), image.clone())]);
    // The 32-byte header, the table count, then the table.
    let mut body = file[32..36].to_vec();
    body.extend(version_1_table(&file[36..], name, &layout));
    let mut file = snapshot::with_header(&body);
    file[8..12].copy_from_slice(&1u32.to_le_bytes());
    let crc = crc32fast::hash(&file[..28]);
    file[28..32].copy_from_slice(&crc.to_le_bytes());
    file
}

/// A version 1 log segment of one record.
fn version_1_segment(name: &str, image: &TableImage) -> Vec<u8> {
    let (layout, _) = image.spec.clone().expect("a layout");
    let mut record = Vec::new();
    wal::encode_record(&mut record, name, image);
    // The record's length and checksum, then its body.
    let body = version_1_table(&record[8..], name, &layout);
    let mut segment = wal::segment_header().to_vec();
    segment[8..12].copy_from_slice(&1u32.to_le_bytes());
    let crc = crc32fast::hash(&segment[..12]);
    segment[12..16].copy_from_slice(&crc.to_le_bytes());
    segment.extend_from_slice(&(body.len() as u32).to_le_bytes());
    segment.extend_from_slice(&crc32fast::hash(&body).to_le_bytes());
    segment.extend_from_slice(&body);
    segment
}

fn legacy() -> ObservationLayout {
    ObservationLayout::legacy("toy", SPEC_LEN as i64)
}

#[tokio::test]
async fn a_version_1_snapshot_restores_and_takes_the_layout_of_the_next_insert() {
    let t = table(50, 0.6);
    insert(&t, 0, 10, None).await;
    let image = t.image();
    let tables = snapshot::decode(&version_1_snapshot("t", &image)).expect("version 1 reads");
    let (name, old) = &tables[0];
    assert_eq!(name, "t");
    assert_eq!(old.spec, Some((legacy(), 4)));
    let rest = TableImage {
        spec: image.spec.clone(),
        ..old.clone()
    };
    assert_eq!(rest, image, "the rest as written");

    let restored = table(50, 0.6);
    restored.restore(old).expect("a legacy layout restores");
    let shutdown = Shutdown::new();
    let s = restored
        .sample(4, 0.5, Duration::from_secs(1), &shutdown)
        .await
        .expect("samples");
    assert_eq!(s.batch.layout, legacy(), "samples say what the file says");

    // Another length is refused; the layout actors send now is taken.
    let mut longer = batch(100, 2, None);
    longer.layout.cols = 3;
    let longer = PreparedBatch::new(ValidBatch::new(longer).expect("valid alone"));
    assert!(restored.insert_now(&longer).is_err(), "18 values, not 12");
    insert(&restored, 100, 3, None).await;
    assert_eq!(restored.image().spec, Some((layout(), 4)));
    let s = restored
        .sample(4, 0.5, Duration::from_secs(1), &shutdown)
        .await
        .expect("samples");
    assert_eq!(s.batch.layout, layout());
    assert_eq!(restored.stats().info.size, 13);
    let again = snapshot::decode(&snapshot::encode(&[("t".to_owned(), restored.image())]))
        .expect("this build's snapshot");
    assert_eq!(again[0].1.spec, Some((layout(), 4)), "written as a layout");
}

#[tokio::test]
async fn a_version_1_log_record_replays_and_the_next_insert_follows_it() {
    let image = prepared(0, 5, None).to_image(0);
    let decoded = wal::decode_segment(&version_1_segment("t", &image)).expect("version 1 reads");
    assert_eq!(decoded.torn, None);
    let (name, old) = &decoded.records[0];
    assert_eq!(name, "t");
    assert_eq!(old.spec, Some((legacy(), 4)));
    let (first_key, logged) = PreparedBatch::from_image(old.clone()).expect("holds together");
    assert_eq!(first_key, 0);

    let t = table(50, 0.6);
    t.insert_now(&logged).expect("the logged batch goes in");
    assert_eq!(t.image().spec, Some((legacy(), 4)));
    insert(&t, 10, 3, None).await;
    assert_eq!(t.image().spec, Some((layout(), 4)));
    assert_eq!(t.stats().info.size, 8);
}
