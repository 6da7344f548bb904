//! A replay snapshot file (`snapshot::decode`) and the tables restored
//! from it (`Table::restore`), as the replay server reads its newest
//! snapshot at start. The first byte picks the input: even, a whole file;
//! odd, a body that `snapshot::with_header` gives a valid header (length
//! and both CRC-32s), so the fuzzer reaches the body's decoder.
//!
//! Asserts: a file that decodes re-encodes to a file that decodes to the
//! same tables (encode -> decode is then a fixed point); restoring an
//! image into a table that holds data either succeeds or leaves the table
//! exactly as it was; a restored table's image restores again to the
//! same image, and every sample it gives is a `ValidBatch` (samples are
//! not checked again before they reach the learner).
#![no_main]

use std::sync::OnceLock;
use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_fuzz::seeds;
use crossroads_replay::snapshot::{self, decode, encode};
use crossroads_replay::{PreparedBatch, TableImage};
use crossroads_types::ValidBatch;
use libfuzzer_sys::fuzz_target;

fn runtime() -> &'static tokio::runtime::Runtime {
    static RT: OnceLock<tokio::runtime::Runtime> = OnceLock::new();
    RT.get_or_init(|| {
        tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .build()
            .expect("a runtime")
    })
}

fn file_of(image: &TableImage) -> Vec<u8> {
    encode(&[("t".to_owned(), image.clone())])
}

fuzz_target!(|data: &[u8]| {
    let Some((&pick, data)) = data.split_first() else {
        return;
    };
    let file = if pick % 2 == 0 {
        data.to_vec()
    } else {
        snapshot::with_header(data)
    };
    let Ok(tables) = decode(&file) else {
        return;
    };
    let again = encode(&tables);
    let decoded = decode(&again).expect("our encoding decodes");
    assert_eq!(encode(&decoded), again, "encode -> decode is a fixed point");

    let shutdown = Shutdown::new();
    for (_, image) in decoded.iter().take(4) {
        let t = seeds::small_table(16);
        let batch = PreparedBatch::new(seeds::dense_batch());
        t.insert_now(&batch).expect("a valid batch");
        let before = file_of(&t.image());
        if t.restore(image).is_err() {
            assert_eq!(
                file_of(&t.image()),
                before,
                "a refused restore changes nothing"
            );
            continue;
        }
        let restored = t.image();
        let fresh = seeds::small_table(16);
        fresh
            .restore(&restored)
            .expect("a table's own image restores");
        assert_eq!(file_of(&fresh.image()), file_of(&restored));
        if restored.is_empty() {
            continue;
        }
        let sample = runtime()
            .block_on(t.sample(8, 0.5, Duration::ZERO, &shutdown))
            .expect("a table with items samples");
        let n = sample.batch.len();
        assert_eq!((sample.keys.len(), sample.weights.len()), (n, n));
        if let Err(e) = ValidBatch::new(sample.batch) {
            panic!("a restored table sampled an invalid batch: {e}");
        }
    }
});
