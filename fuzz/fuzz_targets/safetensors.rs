//! safetensors files of f32 tensors (`crossroads_types::tensors`), the
//! tch-free half of every weights and optimizer-state load (gRPC and
//! shared-memory weights, checkpoint files, `eval --policy` files), and
//! the weights metadata read from their header (`WeightsMeta::read`).
//!
//! Asserts: a file that reads has tensors whose values are their shape's
//! product, its metadata is what the header-only reader says, and writing
//! what was read gives a file that reads back the same (values bit for
//! bit); `WeightsMeta::read` agrees with checking the metadata map.
#![no_main]

use crossroads_types::WeightsMeta;
use crossroads_types::tensors::{read_f32, read_metadata, write_f32};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let header = read_metadata(data);
    if let Ok(metadata) = &header {
        assert_eq!(
            WeightsMeta::read(data),
            WeightsMeta::from_metadata(metadata)
        );
    }
    let Ok((metadata, tensors)) = read_f32(data) else {
        return;
    };
    assert_eq!(header.as_ref(), Ok(&metadata));
    for t in &tensors {
        let n = t
            .shape
            .iter()
            .try_fold(1usize, |n, d| n.checked_mul(*d as usize));
        assert_eq!(n, Some(t.values.len()), "tensor {}", t.name);
    }
    let written = write_f32(&tensors, &metadata).expect("what was read can be written");
    let (metadata2, tensors2) = read_f32(&written).expect("what we wrote reads");
    assert_eq!(metadata2, metadata);
    assert_eq!(tensors2.len(), tensors.len());
    for (a, b) in tensors.iter().zip(&tensors2) {
        assert_eq!((&a.name, &a.shape), (&b.name, &b.shape));
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.values), bits(&b.values));
    }
});
