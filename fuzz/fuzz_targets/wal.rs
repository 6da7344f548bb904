//! The replay's write-ahead log (`wal::decode_segment`) and the batches
//! replayed from it (`PreparedBatch::from_image`), as the replay server
//! reads its log at start. The first byte picks the input: even, a whole
//! segment; odd, one record body that gets a valid segment header and
//! record frame (length and CRC-32), so the fuzzer reaches the record
//! decoder past the checksums.
//!
//! Asserts: reading never goes past the bytes given and reads all of them
//! unless a record is torn; the whole records re-encode to a segment that
//! reads back with nothing torn and re-encodes to the same bytes (a fixed
//! point); every record that makes a batch makes the same batch again from
//! its image, and inserts into an empty table.
#![no_main]

use crossroads_fuzz::seeds;
use crossroads_replay::PreparedBatch;
use crossroads_replay::wal;
use libfuzzer_sys::fuzz_target;

fn encode(records: &[(String, crossroads_replay::TableImage)]) -> Vec<u8> {
    let mut out = wal::segment_header().to_vec();
    for (name, image) in records {
        wal::encode_record(&mut out, name, image);
    }
    out
}

fuzz_target!(|data: &[u8]| {
    let [pick, rest @ ..] = data else {
        return;
    };
    let bytes = if pick % 2 == 0 {
        rest.to_vec()
    } else {
        let mut framed = wal::segment_header().to_vec();
        framed.extend_from_slice(&(rest.len() as u32).to_le_bytes());
        framed.extend_from_slice(&crc32fast::hash(rest).to_le_bytes());
        framed.extend_from_slice(rest);
        framed
    };
    let Ok(decoded) = wal::decode_segment(&bytes) else {
        return;
    };
    assert!(decoded.valid_len <= bytes.len());
    assert_eq!(decoded.torn.is_none(), decoded.valid_len == bytes.len());
    let again = encode(&decoded.records);
    let reread = wal::decode_segment(&again).expect("a header it wrote");
    assert_eq!(reread.torn, None);
    assert_eq!(reread.valid_len, again.len());
    assert_eq!(
        encode(&reread.records),
        again,
        "encode -> decode -> encode is a fixed point"
    );
    for (_, image) in decoded.records {
        let Ok((first_key, batch)) = PreparedBatch::from_image(image) else {
            continue;
        };
        let image = batch.to_image(first_key);
        let (key, same) = PreparedBatch::from_image(image.clone()).expect("its own image");
        assert_eq!(key, first_key);
        assert_eq!(
            encode(&[("t".to_owned(), same.to_image(key))]),
            encode(&[("t".to_owned(), image)])
        );
        seeds::small_table(64)
            .insert_now(&batch)
            .expect("a checked batch inserts");
    }
});
