//! A weights frame read from iceoryx2 shared memory
//! (`weights_shm::read_weights_frame`), as an actor's subscriber reads the
//! newest sample. Input: the `WeightsFrameHeader` field by field, then the
//! safetensors payload.
//!
//! Asserts: accepted weights keep the payload's bytes, their metadata say
//! the header's version and a valid spec, and the publisher's header for
//! them (`weights_frame_header`) is the one they came with.
#![no_main]

use crossroads_fuzz::weights_header_from_bytes;
use crossroads_transport::weights_shm::{read_weights_frame, weights_frame_header};
use crossroads_types::WeightsMeta;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (header, payload) = weights_header_from_bytes(data);
    if let Ok(w) = read_weights_frame(&header, payload.to_vec()) {
        assert_eq!(w.safetensors, payload);
        assert_eq!(weights_frame_header(&w), header);
        let meta = WeightsMeta::read(payload).expect("read once already");
        assert_eq!((meta.version, &meta.spec), (w.version, &w.spec));
        assert_eq!(w.spec.validate(), Ok(()));
        assert!(w.spec.input_len() > 0);
    }
});
