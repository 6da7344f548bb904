//! What the fuzz targets share: how one fuzz input is cut into several
//! byte strings ([`sections`], [`join_sections`]), the `#[repr(C)]` frame
//! headers as plain bytes (field by field, little-endian, no `unsafe`), and
//! the valid inputs the seed corpora are made of ([`seeds`]), built with
//! the real encoders.

use std::collections::HashMap;

use crossroads_transport::shm::{BatchFrameHeader, MAX_KIND, MAX_TABLE};
use crossroads_transport::weights_shm::WeightsFrameHeader;
use crossroads_types::{F32Tensor, NetworkSpec, ObservationLayout, TrunkKind, WeightsMeta};

pub mod seeds;

/// Cuts `data` into `n` sections, each a u32 little-endian length and its
/// bytes; a missing or short section is what is left (possibly empty), so
/// every input means something.
pub fn sections(mut data: &[u8], n: usize) -> Vec<&[u8]> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        if i + 1 == n || data.len() < 4 {
            out.push(data);
            data = &[];
            continue;
        }
        let len = u32::from_le_bytes([data[0], data[1], data[2], data[3]]) as usize;
        let rest = &data[4..];
        let len = len.min(rest.len());
        out.push(&rest[..len]);
        data = &rest[len..];
    }
    out
}

/// The inverse of [`sections`].
pub fn join_sections(parts: &[&[u8]]) -> Vec<u8> {
    let mut out = Vec::new();
    for (i, p) in parts.iter().enumerate() {
        if i + 1 < parts.len() {
            out.extend_from_slice(&(p.len() as u32).to_le_bytes());
        }
        out.extend_from_slice(p);
    }
    out
}

/// Reads little-endian words from the front of a slice, zero past its end.
struct Words<'a>(&'a [u8]);

impl Words<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut b = [0u8; N];
        let n = N.min(self.0.len());
        b[..n].copy_from_slice(&self.0[..n]);
        self.0 = &self.0[n..];
        b
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }
}

/// Bytes of a [`BatchFrameHeader`] in [`batch_header_to_bytes`]' order.
pub const BATCH_HEADER_BYTES: usize = 4 * 11 + 8 + 4 + MAX_KIND + 4 + MAX_TABLE;

/// A batch frame header from its field-by-field bytes, and the rest.
pub fn batch_header_from_bytes(data: &[u8]) -> (BatchFrameHeader, &[u8]) {
    let (head, rest) = data.split_at(data.len().min(BATCH_HEADER_BYTES));
    let mut w = Words(head);
    let mut h = BatchFrameHeader {
        magic: w.u32(),
        version: w.u32(),
        batch_id: w.u64(),
        num_transitions: w.u32(),
        num_observations: w.u32(),
        num_actions: w.u32(),
        encoding: w.u32(),
        data_len: w.u32(),
        channels: w.u32(),
        rows: w.u32(),
        cols: w.u32(),
        extra_features: w.u32(),
        ..BatchFrameHeader::default()
    };
    h.kind_len = w.u32();
    h.kind = w.take();
    h.table_len = w.u32();
    h.table = w.take();
    (h, rest)
}

/// The bytes [`batch_header_from_bytes`] reads.
pub fn batch_header_to_bytes(h: &BatchFrameHeader) -> Vec<u8> {
    let mut out = Vec::with_capacity(BATCH_HEADER_BYTES);
    for v in [h.magic, h.version] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&h.batch_id.to_le_bytes());
    for v in [
        h.num_transitions,
        h.num_observations,
        h.num_actions,
        h.encoding,
        h.data_len,
        h.channels,
        h.rows,
        h.cols,
        h.extra_features,
    ] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&h.kind_len.to_le_bytes());
    out.extend_from_slice(&h.kind);
    out.extend_from_slice(&h.table_len.to_le_bytes());
    out.extend_from_slice(&h.table);
    out
}

/// Bytes of a [`WeightsFrameHeader`].
pub const WEIGHTS_HEADER_BYTES: usize = 32;

/// A weights frame header from its field-by-field bytes, and the rest.
pub fn weights_header_from_bytes(data: &[u8]) -> (WeightsFrameHeader, &[u8]) {
    let (head, rest) = data.split_at(data.len().min(WEIGHTS_HEADER_BYTES));
    let mut w = Words(head);
    let h = WeightsFrameHeader {
        magic: w.u32(),
        frame_version: w.u32(),
        weights_version: w.u64(),
        update_step: w.u64(),
        published_unix_ms: w.u64() as i64,
    };
    (h, rest)
}

/// The bytes [`weights_header_from_bytes`] reads.
pub fn weights_header_to_bytes(h: &WeightsFrameHeader) -> Vec<u8> {
    let mut out = Vec::with_capacity(WEIGHTS_HEADER_BYTES);
    out.extend_from_slice(&h.magic.to_le_bytes());
    out.extend_from_slice(&h.frame_version.to_le_bytes());
    out.extend_from_slice(&h.weights_version.to_le_bytes());
    out.extend_from_slice(&h.update_step.to_le_bytes());
    out.extend_from_slice(&h.published_unix_ms.to_le_bytes());
    out
}

/// A small valid network spec.
pub fn small_spec() -> NetworkSpec {
    NetworkSpec::new(
        ObservationLayout::new("toy", 2, 3, 4, 1),
        "creep",
        TrunkKind::Mlp,
        vec![4],
    )
    .expect("a valid spec")
}

/// A safetensors weights file of `spec` at `version`: one small tensor
/// (the metadata is what a header-only reader checks).
pub fn weights_file(spec: &NetworkSpec, version: u64) -> Vec<u8> {
    let meta = WeightsMeta {
        version,
        spec: spec.clone(),
    };
    let tensors = [F32Tensor {
        name: "value.bias".to_owned(),
        shape: vec![1],
        values: vec![0.5],
    }];
    crossroads_types::tensors::write_f32(&tensors, &meta.to_metadata().expect("metadata"))
        .expect("a valid file")
}

/// Optimizer state as a checkpoint stores it.
pub fn optimizer_file(optimizer: &str, steps: u64) -> Vec<u8> {
    let tensors = [
        F32Tensor {
            name: "square_avg.value.bias".to_owned(),
            shape: vec![1],
            values: vec![0.25],
        },
        F32Tensor {
            name: "square_avg.value.weight".to_owned(),
            shape: vec![1, 2],
            values: vec![0.0, -1.5],
        },
    ];
    let metadata = HashMap::from([
        ("optimizer".to_owned(), optimizer.to_owned()),
        ("steps".to_owned(), steps.to_string()),
    ]);
    crossroads_types::tensors::write_f32(&tensors, &metadata).expect("a valid file")
}

/// f32 values compared by bits, with -0.0 as 0.0 (the sparse encodings
/// drop zeros of either sign).
pub fn bits(values: &[f32]) -> Vec<u32> {
    values
        .iter()
        .map(|v| if *v == 0.0 { 0 } else { v.to_bits() })
        .collect()
}
