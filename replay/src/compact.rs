//! The compact observation format the table stores: lossless, and small for
//! grids whose few non-zero cells repeat a few values.
//!
//! A TTG grid has a handful of cars, each covering 1 to 3 cells whose three
//! channels (heading, speed, occupancy) repeat the car's values. So the
//! format keeps a sorted dictionary of the distinct non-zero values (f32),
//! then per non-empty cell its index as a varint delta, a channel mask
//! and one dictionary reference per set channel (1 byte while the
//! dictionary has at most 256 values). A 5-car grid takes about 100
//! bytes, against 5,616 dense or 240 as sparse pairs.
//!
//! Layout: `varint channels` (1 when the last dimension is above 8: then
//! every value is its own cell), `varint n_values`, `n_values` f32 LE,
//! `varint n_cells`, then per cell `varint (cell - previous - 1)` (the first
//! relative to -1), a `u8` mask when channels > 1, and the references, each
//! `ref_width(n_values)` bytes LE.

use crossroads_types::ObservationLayout;
use crossroads_types::codec::{self, ObservationEncoding};

/// Channels (last dimension) folded into a cell's mask; above this a value
/// is its own cell.
const MAX_MASK_CHANNELS: u32 = 8;

/// The channel count the format uses for observations of this shape.
pub fn channels_of(shape: &[u32]) -> u32 {
    match shape.last() {
        Some(&c) if (1..=MAX_MASK_CHANNELS).contains(&c) => c,
        _ => 1,
    }
}

/// The channel count for observations of `layout`: its last grid
/// dimension (`cols`) taken as the shape's last, as [`channels_of`] reads
/// it. The simulator's grids are wider than 8 columns, so they
/// take 1, as the flat shapes of earlier builds did; either way the format
/// is lossless.
pub fn channels_of_layout(layout: &ObservationLayout) -> u32 {
    channels_of(&[u32::try_from(layout.cols).unwrap_or(0)])
}

fn ref_width(n_values: usize) -> usize {
    match n_values {
        0..=256 => 1,
        257..=65_536 => 2,
        65_537..=16_777_216 => 3,
        _ => 4,
    }
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Reads a varint at `*at`; `None` on a truncated or overlong one.
fn get_varint(bytes: &[u8], at: &mut usize) -> Option<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *bytes.get(*at)?;
        *at += 1;
        v |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return Some(v);
        }
    }
    None
}

/// Encodes the non-zero `(flat index, value)` pairs (strictly increasing
/// indices, finite values) of one observation with `channels` channels.
/// `scratch` is reused between calls to avoid allocations.
pub fn encode_pairs(
    pairs: &[(u32, f32)],
    channels: u32,
    scratch: &mut Vec<u32>,
    out: &mut Vec<u8>,
) {
    scratch.clear();
    scratch.extend(pairs.iter().map(|(_, v)| v.to_bits()));
    scratch.sort_unstable();
    scratch.dedup();
    let dict = &*scratch;
    let width = ref_width(dict.len());
    put_varint(out, u64::from(channels));
    put_varint(out, dict.len() as u64);
    for bits in dict {
        out.extend_from_slice(&bits.to_le_bytes());
    }
    let reference = |v: f32| {
        // The dictionary holds every value of `pairs`.
        let r = dict.binary_search(&v.to_bits()).unwrap_or(0) as u32;
        r.to_le_bytes()
    };
    if channels == 1 {
        // Every value its own cell: no masks, no divisions.
        put_varint(out, pairs.len() as u64);
        let mut previous: i64 = -1;
        for &(i, v) in pairs {
            put_varint(out, (i64::from(i) - previous - 1) as u64);
            previous = i64::from(i);
            out.extend_from_slice(&reference(v)[..width]);
        }
        return;
    }
    let cells = {
        let mut n = 0;
        let mut last = None;
        for (i, _) in pairs {
            let cell = i / channels;
            if last != Some(cell) {
                n += 1;
                last = Some(cell);
            }
        }
        n
    };
    put_varint(out, cells);
    let mut previous: i64 = -1;
    let mut k = 0;
    while k < pairs.len() {
        let cell = pairs[k].0 / channels;
        let mut end = k;
        let mut mask = 0u8;
        while end < pairs.len() && pairs[end].0 / channels == cell {
            mask |= 1 << (pairs[end].0 % channels);
            end += 1;
        }
        put_varint(out, (i64::from(cell) - previous - 1) as u64);
        previous = i64::from(cell);
        out.push(mask);
        for (_, v) in &pairs[k..end] {
            out.extend_from_slice(&reference(*v)[..width]);
        }
        k = end;
    }
}

/// Transcodes one validated wire entry (dense or sparse) of an observation
/// of `len` values with `channels` channels into the compact format.
pub fn from_wire(
    encoding: ObservationEncoding,
    bytes: &[u8],
    len: usize,
    channels: u32,
    pairs: &mut Vec<(u32, f32)>,
    scratch: &mut Vec<u32>,
    out: &mut Vec<u8>,
) {
    pairs.clear();
    match encoding {
        ObservationEncoding::SparseF32 => {
            pairs.extend(codec::sparse_pairs(bytes).filter(|(_, v)| *v != 0.0));
        }
        ObservationEncoding::DenseF32 => {
            for i in 0..len {
                let at = 4 * i;
                let v =
                    f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
                if v != 0.0 {
                    pairs.push((i as u32, v));
                }
            }
        }
    }
    encode_pairs(pairs, channels, scratch, out);
}

/// Why stored bytes do not decode (only a corrupt snapshot can cause it:
/// the table writes what it reads).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("compact observation is malformed at byte {at}")]
pub struct CompactError {
    /// Where decoding stopped.
    pub at: usize,
}

/// Decodes a compact observation into wire sparse pairs appended to `out`
/// (strictly increasing indices, 8 bytes each). Checks every index against
/// `len`, so a corrupt entry is an error, not a panic.
pub fn to_sparse_wire(bytes: &[u8], len: usize, out: &mut Vec<u8>) -> Result<(), CompactError> {
    let mut at = 0;
    let err = |at| CompactError { at };
    let channels = get_varint(bytes, &mut at).ok_or(err(at))?;
    if !(1..=u64::from(MAX_MASK_CHANNELS)).contains(&channels) {
        return Err(err(at));
    }
    let channels = channels as u32;
    let n_values = get_varint(bytes, &mut at).ok_or(err(at))? as usize;
    if n_values > len {
        return Err(err(at));
    }
    let dict_at = at;
    at += 4 * n_values;
    if at > bytes.len() {
        return Err(err(at));
    }
    let value = |r: usize| {
        let p = dict_at + 4 * r;
        [bytes[p], bytes[p + 1], bytes[p + 2], bytes[p + 3]]
    };
    // The table stores only finite values; anything else is corruption.
    if let Some(r) = (0..n_values).find(|r| !f32::from_le_bytes(value(*r)).is_finite()) {
        return Err(err(dict_at + 4 * r));
    }
    let width = ref_width(n_values);
    let n_cells = get_varint(bytes, &mut at).ok_or(err(at))?;
    let mut previous: i64 = -1;
    for _ in 0..n_cells {
        let delta = get_varint(bytes, &mut at).ok_or(err(at))?;
        // Checked: a corrupt delta must not overflow (a cell beyond the
        // observation is an error below anyway).
        let cell = i64::try_from(delta)
            .ok()
            .and_then(|d| (previous + 1).checked_add(d))
            .filter(|cell| *cell < len as i64)
            .ok_or(err(at))?;
        previous = cell;
        let mask = if channels > 1 {
            let m = *bytes.get(at).ok_or(err(at))?;
            at += 1;
            m
        } else {
            1
        };
        for ch in 0..channels {
            if mask & (1 << ch) == 0 {
                continue;
            }
            let index = cell
                .checked_mul(i64::from(channels))
                .and_then(|i| i.checked_add(i64::from(ch)))
                .unwrap_or(i64::MAX);
            if index >= len as i64 {
                return Err(err(at));
            }
            let r_bytes = bytes.get(at..at + width).ok_or(err(at))?;
            at += width;
            let mut r = [0u8; 4];
            r[..width].copy_from_slice(r_bytes);
            let r = u32::from_le_bytes(r) as usize;
            if r >= n_values {
                return Err(err(at));
            }
            out.extend_from_slice(&(index as u32).to_le_bytes());
            out.extend_from_slice(&value(r));
        }
    }
    if at != bytes.len() {
        return Err(err(at));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(values: &[f32], shape: &[u32]) -> usize {
        let mut dense = Vec::new();
        codec::encode_dense(values, &mut dense);
        let mut compact = Vec::new();
        from_wire(
            ObservationEncoding::DenseF32,
            &dense,
            values.len(),
            channels_of(shape),
            &mut Vec::new(),
            &mut Vec::new(),
            &mut compact,
        );
        let mut sparse = Vec::new();
        to_sparse_wire(&compact, values.len(), &mut sparse).expect("decodes");
        let mut back = vec![0.0; values.len()];
        codec::decode_into(ObservationEncoding::SparseF32, &sparse, &mut back).expect("valid");
        assert_eq!(back, values);
        compact.len()
    }

    #[test]
    fn lossless_for_grids_flat_vectors_and_many_values() {
        let mut grid = vec![0.0; 18 * 26 * 3];
        for (cell, (h, s)) in [(40, (0.25, 0.5)), (41, (0.25, 0.5)), (300, (-0.75, 0.1))] {
            grid[cell * 3] = h;
            grid[cell * 3 + 1] = s;
            grid[cell * 3 + 2] = 1.0;
        }
        let size = round_trip(&grid, &[18, 26, 3]);
        assert!(size < 40, "3 cells take {size} bytes");
        round_trip(&[0.0; 10], &[10]);
        let many: Vec<f32> = (0..2000).map(|i| i as f32 * 0.5 - 3.0).collect();
        round_trip(&many, &[2000]);
        let wide: Vec<f32> = (0..40).map(|i| (i % 3) as f32).collect();
        round_trip(&wide, &[2, 20]);
        round_trip(&[-0.0, 1.0, f32::MIN_POSITIVE], &[3]);
    }

    #[test]
    fn corrupt_bytes_are_errors() {
        let mut compact = Vec::new();
        encode_pairs(&[(1, 2.0), (5, 3.0)], 3, &mut Vec::new(), &mut compact);
        let mut out = Vec::new();
        assert!(to_sparse_wire(&compact, 6, &mut out).is_ok());
        assert!(
            to_sparse_wire(&compact, 5, &mut Vec::new()).is_err(),
            "index 5 of 5"
        );
        for cut in 0..compact.len() {
            assert!(to_sparse_wire(&compact[..cut], 6, &mut Vec::new()).is_err());
        }
    }

    /// A cell delta near 2^63 after a first cell overflowed the cell
    /// number (a panic in debug builds), and a NaN in the dictionary came
    /// out as a sample's value; both are corruption of a snapshot.
    #[test]
    fn overflowing_deltas_and_non_finite_values_are_errors() {
        let mut bytes = vec![1, 1];
        bytes.extend_from_slice(&2.0f32.to_le_bytes());
        bytes.push(2);
        bytes.extend_from_slice(&[0, 0]);
        let mut huge = Vec::new();
        put_varint(&mut huge, i64::MAX as u64);
        bytes.extend_from_slice(&huge);
        bytes.push(0);
        assert_eq!(
            to_sparse_wire(&bytes, 6, &mut Vec::new()),
            Err(CompactError { at: 9 + huge.len() })
        );

        let mut nan = Vec::new();
        encode_pairs(&[(1, f32::NAN)], 1, &mut Vec::new(), &mut nan);
        assert_eq!(
            to_sparse_wire(&nan, 6, &mut Vec::new()),
            Err(CompactError { at: 2 })
        );
    }
}
