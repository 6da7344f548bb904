//! Conversion of transition batches between the wire
//! (`crossroads_proto::v1`) and the domain (`crossroads_types::batch`),
//! validating at the boundary: a wire batch becomes a [`TransitionBatch`]
//! only if [`TransitionBatch::validate`] accepts it.

use crossroads_proto::v1 as pb;
use crossroads_types::batch::{
    BatchError, ObservationPool, ObservationSpec, RejectReason, TransitionBatch,
};
use crossroads_types::codec::ObservationEncoding;

/// A wire batch as a validated domain batch. Errors name the field as the
/// wire calls it (`rewards[3]`, `observations.encoding`, ...).
pub fn batch_from_wire(batch: pb::TransitionBatch) -> Result<TransitionBatch, BatchError> {
    let spec = batch
        .spec
        .ok_or_else(|| BatchError::new(RejectReason::Spec, "spec", "missing observation spec"))?;
    let pool = batch.observations.ok_or_else(|| {
        BatchError::new(
            RejectReason::ObservationEncoding,
            "observations",
            "missing observation pool",
        )
    })?;
    let encoding = u32::try_from(pool.encoding)
        .ok()
        .and_then(ObservationEncoding::from_wire)
        .ok_or_else(|| {
            BatchError::new(
                RejectReason::ObservationEncoding,
                "observations.encoding",
                format!(
                    "{} is not a known encoding (1 = dense f32, 2 = sparse f32)",
                    pool.encoding
                ),
            )
        })?;
    let batch = TransitionBatch {
        spec: ObservationSpec {
            kind: spec.kind,
            shape: spec.shape,
        },
        num_actions: batch.num_actions,
        actions: batch.actions,
        rewards: batch.rewards,
        discounts: batch.discounts,
        priorities: batch.priorities,
        observations: ObservationPool::from_parts(encoding, pool.offsets, pool.data),
        observation_index: batch.observation_index,
        next_observation_index: batch.next_observation_index,
    };
    batch.validate()?;
    Ok(batch)
}

/// A domain batch on the wire.
pub fn batch_to_wire(batch: TransitionBatch) -> pb::TransitionBatch {
    let (encoding, offsets, data) = batch.observations.into_parts();
    pb::TransitionBatch {
        spec: Some(pb::ObservationSpec {
            kind: batch.spec.kind,
            shape: batch.spec.shape,
        }),
        num_actions: batch.num_actions,
        actions: batch.actions,
        rewards: batch.rewards,
        discounts: batch.discounts,
        priorities: batch.priorities,
        observations: Some(pb::ObservationPool {
            encoding: encoding.to_wire() as i32,
            offsets,
            data,
        }),
        observation_index: batch.observation_index,
        next_observation_index: batch.next_observation_index,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crossroads_types::batch::Transition;

    #[test]
    fn round_trip_and_boundary_errors() {
        let mut b = TransitionBatch::new(
            ObservationSpec::new("toy", [4]),
            2,
            ObservationEncoding::DenseF32,
        );
        let o = b.push_observation(&[1.0, 0.0, 0.0, 2.0]);
        b.push(Transition {
            observation: o,
            action: 1,
            reward: -1.0,
            discount: 0.0,
            priority: 1.0,
            next_observation: o,
        });
        let wire = batch_to_wire(b.clone());
        assert_eq!(batch_from_wire(wire.clone()), Ok(b));

        let mut bad = wire.clone();
        bad.observations.as_mut().expect("pool").encoding = 7;
        let err = batch_from_wire(bad).expect_err("unknown encoding");
        assert_eq!(err.field, "observations.encoding");

        let mut bad = wire;
        bad.spec = None;
        assert_eq!(batch_from_wire(bad).expect_err("no spec").field, "spec");
    }
}
