//! The observation codec: how one observation's f32 values are laid out in
//! bytes, the same for gRPC `bytes` fields and iceoryx2 slices.
//!
//! Two encodings, both little-endian:
//! - [`ObservationEncoding::DenseF32`]: every value, row-major, 4 bytes each.
//! - [`ObservationEncoding::SparseF32`]: only the non-zero cells, as
//!   `(u32 flat index, f32 value)` pairs with strictly increasing indices,
//!   8 bytes each. Grid observations are mostly empty, so this is the
//!   encoding actors should send.
//!
//! [`check`] validates an encoded entry against an observation length
//! without decoding it into a buffer; [`decode_into`] writes the values.

/// How observation values are laid out in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ObservationEncoding {
    /// Little-endian f32 values, row-major.
    DenseF32,
    /// `(u32 index, f32 value)` pairs of the non-zero cells, little-endian,
    /// indices strictly increasing.
    SparseF32,
}

impl ObservationEncoding {
    /// The wire number (`crossroads.v1.ObservationEncoding`).
    pub fn to_wire(self) -> u32 {
        match self {
            ObservationEncoding::DenseF32 => 1,
            ObservationEncoding::SparseF32 => 2,
        }
    }

    /// The encoding of a wire number, if known.
    pub fn from_wire(value: u32) -> Option<Self> {
        match value {
            1 => Some(ObservationEncoding::DenseF32),
            2 => Some(ObservationEncoding::SparseF32),
            _ => None,
        }
    }
}

/// Why an encoded observation is not valid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CodecError {
    /// The byte length does not fit the encoding and observation length.
    #[error("{got} bytes, expected {expected}")]
    Length {
        /// What the encoding needs, e.g. `1872` or `a multiple of 8`.
        expected: String,
        /// Bytes found.
        got: usize,
    },
    /// A sparse index is outside the observation.
    #[error("cell index {index} is outside the observation of {len} values")]
    IndexRange {
        /// The index.
        index: u32,
        /// The observation's length.
        len: usize,
    },
    /// Sparse indices must be strictly increasing (so each cell appears
    /// once).
    #[error("cell index {index} does not follow {previous} (indices must be strictly increasing)")]
    IndexOrder {
        /// The index.
        index: u32,
        /// The index before it.
        previous: u32,
    },
    /// A value is NaN or infinite.
    #[error("value {value} at cell {index} is not finite")]
    NonFinite {
        /// Flat index of the cell.
        index: u32,
        /// The value.
        value: f32,
    },
}

const PAIR: usize = 8;

fn f32_at(bytes: &[u8], at: usize) -> f32 {
    f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

/// Appends `values` densely to `out`.
pub fn encode_dense(values: &[f32], out: &mut Vec<u8>) {
    out.reserve(values.len() * 4);
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// The non-zero values of `values` as `(index, value)` pairs, in order
/// (the inverse of [`spread_pairs`]).
pub fn nonzero_pairs(values: &[f32]) -> Vec<(u32, f32)> {
    let mut pairs = Vec::new();
    for_each_nonzero(values, |i, v| pairs.push((i as u32, v)));
    pairs
}

/// Calls `f(index, value)` for each value of `values` that is not zero
/// (of either sign; NaN is not zero), in order. Skips zeros 16 at a time
/// with a test that vectorizes: most of an observation is zeros.
pub fn for_each_nonzero(values: &[f32], mut f: impl FnMut(usize, f32)) {
    for (c, chunk) in values.chunks(16).enumerate() {
        // All zero: no bit set but the sign bits. A fold without an early
        // exit, so it vectorizes.
        if chunk.iter().fold(0u32, |a, v| a | (v.to_bits() << 1)) == 0 {
            continue;
        }
        for (k, &v) in chunk.iter().enumerate() {
            if v != 0.0 {
                f(c * 16 + k, v);
            }
        }
    }
}

/// Appends the non-zero cells of `values` as sparse pairs to `out`.
/// Negative zero counts as zero.
pub fn encode_sparse(values: &[f32], out: &mut Vec<u8>) {
    for_each_nonzero(values, |i, v| {
        // Observations are far below 2^32 values (checked by callers
        // through the spec's length).
        out.extend_from_slice(&(i as u32).to_le_bytes());
        out.extend_from_slice(&v.to_le_bytes());
    });
}

/// Appends `values` to `out` in `encoding`.
pub fn encode(encoding: ObservationEncoding, values: &[f32], out: &mut Vec<u8>) {
    match encoding {
        ObservationEncoding::DenseF32 => encode_dense(values, out),
        ObservationEncoding::SparseF32 => encode_sparse(values, out),
    }
}

/// Appends an observation of `len` values given as its non-zero values
/// (`(index, value)`, increasing indices below `len`) to `out` in
/// `encoding`: the same bytes [`encode`] writes for the dense values, and
/// for the sparse encoding without a pass over the zeros.
pub fn encode_pairs(
    encoding: ObservationEncoding,
    pairs: &[(u32, f32)],
    len: usize,
    out: &mut Vec<u8>,
) {
    match encoding {
        ObservationEncoding::SparseF32 => {
            out.reserve(pairs.len() * PAIR);
            for &(i, v) in pairs.iter().filter(|(_, v)| *v != 0.0) {
                out.extend_from_slice(&i.to_le_bytes());
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        ObservationEncoding::DenseF32 => {
            let mut row = vec![0.0; len];
            // Out-of-range pairs are dropped, as `encode` of the row would.
            let _ = spread_pairs(pairs.iter().copied(), &mut row);
            encode(encoding, &row, out);
        }
    }
}

/// Writes `(index, value)` pairs into the dense row `row`: every value of
/// the row is written, zero where no pair names it, and a later pair for the
/// same index wins. The one place pairs become dense values (the actor's
/// dense batch, a network that reads dense rows, [`decode_into`]). A pair
/// past the row's end is an error naming it; the pairs before it are
/// written, the rest are not.
pub fn spread_pairs(
    pairs: impl IntoIterator<Item = (u32, f32)>,
    row: &mut [f32],
) -> Result<(), CodecError> {
    row.fill(0.0);
    let len = row.len();
    for (index, value) in pairs {
        *row.get_mut(index as usize)
            .ok_or(CodecError::IndexRange { index, len })? = value;
    }
    Ok(())
}

/// Checks that `bytes` is a valid observation of `len` values in
/// `encoding`: the right length, indices in range and increasing, every
/// value finite. Returns the number of non-zero values.
pub fn check(encoding: ObservationEncoding, bytes: &[u8], len: usize) -> Result<usize, CodecError> {
    match encoding {
        ObservationEncoding::DenseF32 => {
            if bytes.len() != len * 4 {
                return Err(CodecError::Length {
                    expected: (len * 4).to_string(),
                    got: bytes.len(),
                });
            }
            let mut non_zero = 0;
            for i in 0..len {
                let value = f32_at(bytes, i * 4);
                if !value.is_finite() {
                    return Err(CodecError::NonFinite {
                        index: i as u32,
                        value,
                    });
                }
                non_zero += usize::from(value != 0.0);
            }
            Ok(non_zero)
        }
        ObservationEncoding::SparseF32 => {
            if !bytes.len().is_multiple_of(PAIR) || bytes.len() / PAIR > len {
                return Err(CodecError::Length {
                    expected: format!("a multiple of {PAIR}, at most {}", len * PAIR),
                    got: bytes.len(),
                });
            }
            let mut previous: Option<u32> = None;
            for pair in 0..bytes.len() / PAIR {
                let index = u32_at(bytes, pair * PAIR);
                let value = f32_at(bytes, pair * PAIR + 4);
                if index as usize >= len {
                    return Err(CodecError::IndexRange { index, len });
                }
                if let Some(previous) = previous.filter(|p| index <= *p) {
                    return Err(CodecError::IndexOrder { index, previous });
                }
                if !value.is_finite() {
                    return Err(CodecError::NonFinite { index, value });
                }
                previous = Some(index);
            }
            Ok(bytes.len() / PAIR)
        }
    }
}

/// Decodes a valid entry (see [`check`]) into `out`, whose length is the
/// observation's. Every value of `out` is written.
pub fn decode_into(
    encoding: ObservationEncoding,
    bytes: &[u8],
    out: &mut [f32],
) -> Result<(), CodecError> {
    check(encoding, bytes, out.len())?;
    match encoding {
        ObservationEncoding::DenseF32 => {
            for (i, v) in out.iter_mut().enumerate() {
                *v = f32_at(bytes, i * 4);
            }
        }
        ObservationEncoding::SparseF32 => spread_pairs(sparse_pairs(bytes), out)?,
    }
    Ok(())
}

/// The `(index, value)` pairs of a sparse entry (trailing partial pairs
/// are ignored; [`check`] rejects them).
pub fn sparse_pairs(bytes: &[u8]) -> impl Iterator<Item = (u32, f32)> + '_ {
    bytes
        .chunks_exact(PAIR)
        .map(|c| (u32_at(c, 0), f32_at(c, 4)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_pairs_writes_every_value_and_names_an_index_past_the_end() {
        let mut row = vec![7.0; 5];
        spread_pairs([(1, 1.5), (3, -2.0), (3, 4.0)], &mut row).expect("in range");
        assert_eq!(
            row,
            [0.0, 1.5, 0.0, 4.0, 0.0],
            "zeros elsewhere, the later pair wins"
        );
        assert_eq!(nonzero_pairs(&row), [(1, 1.5), (3, 4.0)], "and back");
        let err = spread_pairs([(0, 1.0), (5, 2.0)], &mut row).expect_err("past the end");
        assert_eq!(err, CodecError::IndexRange { index: 5, len: 5 });
        assert!(err.to_string().contains("index 5"), "{err}");
    }

    #[test]
    fn pairs_encode_to_the_bytes_of_their_dense_values() {
        let values = [0.0, 1.5, 0.0, -2.0, 0.0, 0.25, 0.0];
        let pairs = [(1, 1.5), (3, -2.0), (5, 0.25)];
        for encoding in [
            ObservationEncoding::DenseF32,
            ObservationEncoding::SparseF32,
        ] {
            let (mut from_values, mut from_pairs) = (vec![9], vec![9]);
            encode(encoding, &values, &mut from_values);
            encode_pairs(encoding, &pairs, values.len(), &mut from_pairs);
            assert_eq!(from_pairs, from_values, "{encoding:?}");
        }
    }

    #[test]
    fn dense_and_sparse_round_trip() {
        let values = [0.0, 1.5, 0.0, -2.0, 0.0, 0.25];
        for encoding in [
            ObservationEncoding::DenseF32,
            ObservationEncoding::SparseF32,
        ] {
            let mut bytes = Vec::new();
            encode(encoding, &values, &mut bytes);
            assert_eq!(check(encoding, &bytes, values.len()), Ok(3));
            let mut out = [9.0; 6];
            decode_into(encoding, &bytes, &mut out).expect("valid");
            assert_eq!(out, values);
        }
        let mut sparse = Vec::new();
        encode_sparse(&values, &mut sparse);
        assert_eq!(sparse.len(), 3 * 8, "only non-zero cells");
    }

    #[test]
    fn every_non_zero_value_is_found_across_the_runs_of_sixteen() {
        // Values at the edges of the 16-value runs, a whole zero run, a
        // negative zero (a zero), NaN and infinity (not zeros), a short
        // last run.
        let mut values = vec![0.0f32; 53];
        for (i, v) in [
            (0, 1.0),
            (15, -2.0),
            (16, f32::NAN),
            (31, 0.5),
            (52, f32::INFINITY),
        ] {
            values[i] = v;
        }
        values[40] = -0.0;
        let mut found = Vec::new();
        for_each_nonzero(&values, |i, v| found.push((i, v.to_bits())));
        let want: Vec<_> = values
            .iter()
            .enumerate()
            .filter(|(_, v)| **v != 0.0)
            .map(|(i, v)| (i, v.to_bits()))
            .collect();
        assert_eq!(found, want);
        assert_eq!(
            found.iter().map(|p| p.0).collect::<Vec<_>>(),
            [0, 15, 16, 31, 52]
        );
    }

    #[test]
    fn invalid_entries_are_named() {
        use ObservationEncoding::*;
        assert!(matches!(
            check(DenseF32, &[0; 7], 2),
            Err(CodecError::Length { got: 7, .. })
        ));
        let mut nan = Vec::new();
        encode_dense(&[0.0, f32::NAN], &mut nan);
        assert!(matches!(
            check(DenseF32, &nan, 2),
            Err(CodecError::NonFinite { index: 1, .. })
        ));
        let pair = |i: u32, v: f32| [i.to_le_bytes(), v.to_le_bytes()].concat();
        assert!(matches!(
            check(SparseF32, &pair(5, 1.0), 5),
            Err(CodecError::IndexRange { index: 5, len: 5 })
        ));
        let unordered = [pair(3, 1.0), pair(3, 1.0)].concat();
        assert!(matches!(
            check(SparseF32, &unordered, 5),
            Err(CodecError::IndexOrder { .. })
        ));
        assert!(matches!(
            check(SparseF32, &pair(1, f32::INFINITY), 5),
            Err(CodecError::NonFinite { index: 1, .. })
        ));
        assert!(matches!(
            check(SparseF32, &[0; 12], 5),
            Err(CodecError::Length { got: 12, .. })
        ));
    }
}
