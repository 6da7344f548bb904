//! The observation codec (`crossroads_types::codec`), dense and sparse, as
//! every received batch's pool entries go through it. Input: an encoding
//! byte (even dense, odd sparse), the observation length (u16, little
//! endian, at most 4096), then the encoded bytes.
//!
//! Asserts: `check` and `decode_into` agree; a failed decode leaves the
//! output untouched; a decoded observation is finite, its non-zero count
//! is what `check` said, and it survives encode -> check -> decode in both
//! encodings bit for bit (a dense entry re-encodes to the same bytes).
#![no_main]

use crossroads_fuzz::bits;
use crossroads_types::codec::{self, ObservationEncoding};
use libfuzzer_sys::fuzz_target;

const ENCODINGS: [ObservationEncoding; 2] = [
    ObservationEncoding::DenseF32,
    ObservationEncoding::SparseF32,
];

fuzz_target!(|data: &[u8]| {
    let [pick, l0, l1, bytes @ ..] = data else {
        return;
    };
    let encoding = ENCODINGS[usize::from(pick % 2)];
    let len = usize::from(u16::from_le_bytes([*l0, *l1])) % 4097;
    let checked = codec::check(encoding, bytes, len);
    let sentinel = f32::from_bits(0x7fc0_1234);
    let mut out = vec![sentinel; len];
    let decoded = codec::decode_into(encoding, bytes, &mut out);
    assert_eq!(checked.is_ok(), decoded.is_ok());
    let Ok(count) = checked else {
        assert!(
            out.iter().all(|v| v.to_bits() == sentinel.to_bits()),
            "partial output"
        );
        return;
    };
    assert!(out.iter().all(|v| v.is_finite()));
    let non_zero = out.iter().filter(|v| **v != 0.0).count();
    match encoding {
        ObservationEncoding::DenseF32 => {
            assert_eq!(count, non_zero);
            let mut again = Vec::new();
            codec::encode_dense(&out, &mut again);
            assert_eq!(again, bytes);
        }
        // Pairs may hold explicit zeros; the decoded values cannot hold more.
        ObservationEncoding::SparseF32 => assert!(non_zero <= count && count == bytes.len() / 8),
    }
    for e in ENCODINGS {
        let mut encoded = Vec::new();
        codec::encode(e, &out, &mut encoded);
        assert_eq!(codec::check(e, &encoded, len), Ok(non_zero));
        let mut back = vec![1.0; len];
        codec::decode_into(e, &encoded, &mut back).expect("our encoding decodes");
        assert_eq!(bits(&back), bits(&out));
    }
});
