//! A replay request's batch from protobuf bytes (`wire::batch_from_wire`),
//! and a sample response (`wire::sample_from_wire`), as the replay server
//! and the learner receive them.
//!
//! Asserts: a batch that converts is a `ValidBatch` whose every invariant
//! holds (equal columns, actions below `num_actions`, finite rewards,
//! discounts in [0, 1], finite non-negative priorities, indices into the
//! pool, every pool entry decoding to the layout's length), converts back to
//! the very message it came from, and survives encode -> decode ->
//! convert unchanged; a refused one names its field. A sample that
//! converts has one key and weight per transition.
#![no_main]

use crossroads_proto::v1 as pb;
use crossroads_transport::wire;
use crossroads_types::ValidBatch;
use libfuzzer_sys::fuzz_target;
use prost::Message;

fn check_invariants(b: &ValidBatch) {
    let c = &b.columns;
    let n = b.len();
    assert!(n > 0);
    for len in [
        c.rewards.len(),
        c.discounts.len(),
        c.priorities.len(),
        c.observation_index.len(),
        c.next_observation_index.len(),
    ] {
        assert_eq!(len, n);
    }
    assert!(c.actions.iter().all(|a| *a < b.num_actions));
    assert!(c.rewards.iter().all(|r| r.is_finite()));
    assert!(c.discounts.iter().all(|d| (0.0..=1.0).contains(d)));
    assert!(c.priorities.iter().all(|p| p.is_finite() && *p >= 0.0));
    let pool = &b.observations;
    let indices = c.observation_index.iter().chain(&c.next_observation_index);
    assert!(indices.into_iter().all(|i| (*i as usize) < pool.len()));
    let len = b.layout.check().expect("a valid layout has a length");
    let mut out = vec![0.0; len];
    for i in 0..pool.len() {
        pool.decode_into(i, &mut out).expect("every entry decodes");
        assert!(out.iter().all(|v| v.is_finite()));
    }
}

fuzz_target!(|data: &[u8]| {
    if let Ok(message) = pb::TransitionBatch::decode(data) {
        match wire::batch_from_wire(message.clone()) {
            Ok(batch) => {
                check_invariants(&batch);
                let back = wire::batch_to_wire(batch.clone().into_inner());
                assert_eq!(back, message, "the domain batch carries every field");
                let again = pb::TransitionBatch::decode(back.encode_to_vec().as_slice())
                    .expect("our encoding decodes");
                assert_eq!(wire::batch_from_wire(again), Ok(batch));
            }
            Err(e) => assert!(!e.field.is_empty(), "an error names its field"),
        }
    }
    if let Ok(response) = pb::SampleResponse::decode(data)
        && let Ok(sample) = wire::sample_from_wire(response)
    {
        check_invariants(&sample.batch);
        assert_eq!(sample.keys.len(), sample.batch.len());
        assert_eq!(sample.weights.len(), sample.batch.len());
    }
});
