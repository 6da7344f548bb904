//! A batch frame read from iceoryx2 shared memory (`shm::read_frame`), as
//! the replay server's ingest thread reads every received sample. Input: a
//! flags byte, the `BatchFrameHeader` field by field, then the payload.
//! Flag bit 0 sets the header's `data_len` to what the payload leaves, so
//! the fuzzer reaches past the length check more often.
//!
//! Asserts: an accepted frame is a valid batch which, framed again by the
//! publisher's code (`BatchFrameHeader::for_batch`, `write_frame`), gives
//! the same header fields and the same payload bytes, and reads back
//! equal; a refused frame names its field.
#![no_main]

use crossroads_fuzz::batch_header_from_bytes;
use crossroads_transport::shm::{self, BatchFrameHeader};
use crossroads_types::columns::ROW_BYTES;
use libfuzzer_sys::fuzz_target;

fn used(h: &BatchFrameHeader) -> impl PartialEq + std::fmt::Debug {
    (
        (h.magic, h.version, h.batch_id),
        (h.num_transitions, h.num_observations, h.num_actions),
        (h.encoding, h.data_len),
        (h.channels, h.rows, h.cols, h.extra_features),
        h.kind[..h.kind_len as usize].to_vec(),
        h.table[..h.table_len as usize].to_vec(),
    )
}

fuzz_target!(|data: &[u8]| {
    let Some((&flags, data)) = data.split_first() else {
        return;
    };
    let (mut header, payload) = batch_header_from_bytes(data);
    if flags & 1 == 1 {
        let fixed = ROW_BYTES as u64 * u64::from(header.num_transitions)
            + 4 * u64::from(header.num_observations);
        if let Some(rest) = (payload.len() as u64).checked_sub(fixed) {
            header.data_len = u32::try_from(rest).unwrap_or(u32::MAX);
        }
    }
    match shm::read_frame(&header, payload) {
        Ok((table, batch_id, batch)) => {
            assert_eq!(batch_id, header.batch_id);
            let (again, len) =
                BatchFrameHeader::for_batch(&table, batch_id, &batch).expect("it came in a frame");
            assert_eq!(used(&again), used(&header));
            assert_eq!(len, payload.len());
            let mut bytes = vec![0; len];
            shm::write_frame(&batch, &mut bytes);
            assert_eq!(bytes, payload);
            assert_eq!(
                shm::read_frame(&again, &bytes),
                Ok((table, batch_id, batch))
            );
        }
        Err(e) => assert!(!e.field.is_empty(), "an error names its field"),
    }
});
