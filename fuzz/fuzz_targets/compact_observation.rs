//! The replay table's compact observation format (`compact`), which a
//! restored snapshot's observations are in and every sample decodes
//! (`compact::to_sparse_wire`). The first byte picks the direction: even,
//! decode the bytes after the observation length (u16 little-endian, at
//! most 4096); odd, encode the bytes after the second as f32 values
//! (non-finite ones read as zero) with the channel count the second byte
//! gives, and decode.
//!
//! Asserts: decoding either fails or gives a sparse entry that the wire
//! codec accepts for that length, which encodes again (`from_wire`) to a
//! compact entry decoding to the same values; encoding any finite values
//! and decoding gives them back bit for bit (zeros of either sign as 0).
#![no_main]

use crossroads_fuzz::bits;
use crossroads_replay::compact;
use crossroads_types::codec::{self, ObservationEncoding};
use libfuzzer_sys::fuzz_target;

fn dense(sparse: &[u8], len: usize) -> Vec<f32> {
    let mut out = vec![0.0; len];
    codec::decode_into(ObservationEncoding::SparseF32, sparse, &mut out).expect("valid sparse");
    out
}

fuzz_target!(|data: &[u8]| {
    let [pick, a, rest @ ..] = data else {
        return;
    };
    if pick % 2 == 0 {
        let [b, rest @ ..] = rest else {
            return;
        };
        let len = usize::from(u16::from_le_bytes([*a, *b])) % 4097;
        let mut sparse = Vec::new();
        if compact::to_sparse_wire(rest, len, &mut sparse).is_err() {
            return;
        }
        assert!(codec::check(ObservationEncoding::SparseF32, &sparse, len).is_ok());
        let values = dense(&sparse, len);
        let channels = compact::channels_of(&[(*a as u32) % 10]);
        let mut again = Vec::new();
        compact::from_wire(
            ObservationEncoding::SparseF32,
            &sparse,
            len,
            channels,
            &mut Vec::new(),
            &mut Vec::new(),
            &mut again,
        );
        let mut sparse2 = Vec::new();
        compact::to_sparse_wire(&again, len, &mut sparse2).expect("our encoding decodes");
        assert_eq!(bits(&dense(&sparse2, len)), bits(&values));
    } else {
        let values: Vec<f32> = rest
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .map(|v| if v.is_finite() { v } else { 0.0 })
            .collect();
        let shape = [u32::from(*a) % 10];
        let mut dense_bytes = Vec::new();
        codec::encode_dense(&values, &mut dense_bytes);
        let mut compact_bytes = Vec::new();
        compact::from_wire(
            ObservationEncoding::DenseF32,
            &dense_bytes,
            values.len(),
            compact::channels_of(&shape),
            &mut Vec::new(),
            &mut Vec::new(),
            &mut compact_bytes,
        );
        let mut sparse = Vec::new();
        compact::to_sparse_wire(&compact_bytes, values.len(), &mut sparse)
            .expect("our encoding decodes");
        assert_eq!(bits(&dense(&sparse, values.len())), bits(&values));
    }
});
