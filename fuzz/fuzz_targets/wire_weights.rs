//! Weights and network specs from protobuf bytes (`convert::weights_from_wire`,
//! `convert::spec_from_wire`), as actors and the CLI receive them from the
//! learner. The first byte picks the message: even `Weights`, odd
//! `NetworkSpec`.
//!
//! Asserts: an accepted spec is valid and has an observation length
//! (`input_len` does not overflow), and converts back to the same spec;
//! accepted weights say the message's version and spec in their
//! safetensors metadata and convert back to the message they came from.
#![no_main]

use crossroads_proto::v1 as pb;
use crossroads_transport::convert;
use crossroads_types::{NetworkSpec, WeightsMeta};
use libfuzzer_sys::fuzz_target;
use prost::Message;

fn check_spec(spec: &NetworkSpec) {
    assert_eq!(spec.validate(), Ok(()));
    let len = spec.input_len();
    assert!(len > 0 && len <= crossroads_types::batch::MAX_OBSERVATION_LEN as i64);
    assert_eq!(
        convert::spec_from_wire(convert::spec_to_wire(spec)).as_ref(),
        Ok(spec)
    );
}

fuzz_target!(|data: &[u8]| {
    let Some((&pick, data)) = data.split_first() else {
        return;
    };
    if pick % 2 == 0 {
        let Ok(message) = pb::Weights::decode(data) else {
            return;
        };
        if let Ok(w) = convert::weights_from_wire(message.clone()) {
            check_spec(&w.spec);
            let meta = WeightsMeta::read(&w.safetensors).expect("read once already");
            assert_eq!((meta.version, &meta.spec), (w.version, &w.spec));
            let back = convert::weights_to_wire(&w);
            assert_eq!(back.safetensors, message.safetensors);
            assert_eq!(
                (back.version, back.update_step, back.published_unix_ms),
                (
                    message.version,
                    message.update_step,
                    message.published_unix_ms
                )
            );
            assert_eq!(convert::weights_from_wire(back), Ok(w));
        }
    } else if let Ok(message) = pb::NetworkSpec::decode(data)
        && let Ok(spec) = convert::spec_from_wire(message)
    {
        check_spec(&spec);
    }
});
