//! Conversion of the replay's messages between the wire
//! (`crossroads_proto::v1`) and the domain (`crossroads_types`), validating
//! at the boundary: a wire batch becomes a [`ValidBatch`] only if
//! [`TransitionBatch::validate`] accepts it, so this is the one check a
//! received batch gets.

use crossroads_proto::v1 as pb;
use crossroads_types::batch::{
    BatchError, ObservationPool, RejectReason, TransitionBatch, ValidBatch,
};
use crossroads_types::codec::ObservationEncoding;
use crossroads_types::{Columns, Sample};

use crate::convert::{layout_from_wire, layout_to_wire};
use crate::grpc::{RateLimiterInfo, TableInfo};

/// A wire batch as a validated domain batch. Errors name the field as the
/// wire calls it (`rewards[3]`, `observations.encoding`, `spec.shape`,
/// ...); the batch's layout travels in `spec`.
pub fn batch_from_wire(batch: pb::TransitionBatch) -> Result<ValidBatch, BatchError> {
    let spec = batch
        .spec
        .ok_or_else(|| BatchError::new(RejectReason::Spec, "spec", "missing observation spec"))?;
    let layout = layout_from_wire(spec)
        .map_err(|problem| BatchError::new(RejectReason::Spec, "spec.shape", problem))?;
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
    ValidBatch::new(TransitionBatch {
        layout,
        num_actions: batch.num_actions,
        columns: Columns {
            actions: batch.actions,
            rewards: batch.rewards,
            discounts: batch.discounts,
            priorities: batch.priorities,
            observation_index: batch.observation_index,
            next_observation_index: batch.next_observation_index,
        },
        observations: ObservationPool::from_parts(encoding, pool.offsets, pool.data),
    })
}

/// A domain batch on the wire.
pub fn batch_to_wire(batch: TransitionBatch) -> pb::TransitionBatch {
    let (encoding, offsets, data) = batch.observations.into_parts();
    let c = batch.columns;
    pb::TransitionBatch {
        spec: Some(layout_to_wire(&batch.layout)),
        num_actions: batch.num_actions,
        actions: c.actions,
        rewards: c.rewards,
        discounts: c.discounts,
        priorities: c.priorities,
        observations: Some(pb::ObservationPool {
            encoding: encoding.to_wire() as i32,
            offsets,
            data,
        }),
        observation_index: c.observation_index,
        next_observation_index: c.next_observation_index,
    }
}

/// A sample as the replay server answers it. The wire repeats the
/// priorities beside the batch; they are the batch's `priorities` column.
pub fn sample_to_wire(sample: Sample<TransitionBatch>) -> pb::SampleResponse {
    pb::SampleResponse {
        keys: sample.keys,
        weights: sample.weights,
        priorities: sample.batch.columns.priorities.clone(),
        batch: Some(batch_to_wire(sample.batch)),
    }
}

/// A sample response as a domain sample: the batch validated, and one key,
/// weight and priority per transition.
pub fn sample_from_wire(response: pb::SampleResponse) -> Result<Sample, BatchError> {
    let batch = response
        .batch
        .ok_or_else(|| {
            BatchError::new(
                RejectReason::BadRequest,
                "batch",
                "missing from the sample response",
            )
        })
        .and_then(batch_from_wire)?;
    let n = batch.len();
    if response.keys.len() != n || response.weights.len() != n || response.priorities.len() != n {
        return Err(BatchError::new(
            RejectReason::LengthMismatch,
            "keys",
            format!(
                "{} keys, {} weights, {} priorities for {n} transitions",
                response.keys.len(),
                response.weights.len(),
                response.priorities.len()
            ),
        ));
    }
    Ok(Sample {
        keys: response.keys,
        weights: response.weights,
        batch,
    })
}

/// A table description moved field by field between the domain's and the
/// wire's structs of the same fields (`TableInfo`, `RateLimiterInfo`), so
/// both directions name the fields once.
macro_rules! table_info {
    ($i:ident => $($table:ident)::+, $($limiter:ident)::+) => {
        $($table)::+ {
            name: $i.name,
            size: $i.size,
            capacity: $i.capacity,
            inserts_total: $i.inserts_total,
            samples_total: $i.samples_total,
            priority_updates_total: $i.priority_updates_total,
            ignored_updates_total: $i.ignored_updates_total,
            rejections_total: $i.rejections_total.into_iter().collect(),
            rate_limiter: $i.rate_limiter.map(|r| $($limiter)::+ {
                min_size_to_sample: r.min_size_to_sample,
                samples_per_insert: r.samples_per_insert,
                error_tolerance: r.error_tolerance,
                can_sample: r.can_sample,
                can_insert: r.can_insert,
                sample_waits_total: r.sample_waits_total,
                insert_waits_total: r.insert_waits_total,
            }),
            bytes_stored: $i.bytes_stored,
            last_snapshot_unix_ms: $i.last_snapshot_unix_ms,
        }
    };
}

/// A table's description on the wire.
pub fn table_info_to_wire(i: TableInfo) -> pb::TableInfo {
    table_info!(i => pb::TableInfo, pb::RateLimiterInfo)
}

/// A table's description from the wire.
pub fn table_info_from_wire(i: pb::TableInfo) -> TableInfo {
    table_info!(i => TableInfo, RateLimiterInfo)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crossroads_types::ObservationLayout;
    use crossroads_types::batch::Transition;

    #[test]
    fn round_trip_and_boundary_errors() {
        let mut b = TransitionBatch::new(
            ObservationLayout::new("toy", 1, 1, 3, 1),
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
        assert_eq!(
            batch_from_wire(wire.clone()).map(ValidBatch::into_inner),
            Ok(b)
        );

        let mut bad = wire.clone();
        bad.observations.as_mut().expect("pool").encoding = 7;
        let err = batch_from_wire(bad).expect_err("unknown encoding");
        assert_eq!(err.field, "observations.encoding");

        let mut bad = wire.clone();
        bad.spec = None;
        assert_eq!(batch_from_wire(bad).expect_err("no spec").field, "spec");

        // The layout travels as [channels, rows, cols] and extra_features;
        // an earlier build's flat [len] is refused, naming what is expected.
        let spec = wire.spec.as_ref().expect("spec");
        assert_eq!(spec.shape, vec![1, 1, 3]);
        assert_eq!(spec.extra_features, 1);
        let mut flat = wire;
        flat.spec = Some(pb::ObservationSpec {
            kind: "toy".to_owned(),
            shape: vec![4],
            extra_features: 0,
        });
        let err = batch_from_wire(flat).expect_err("a flat shape");
        assert_eq!(
            (err.reason, err.field.as_str()),
            (RejectReason::Spec, "spec.shape")
        );
        assert!(err.problem.contains("[channels, rows, cols]"), "{err}");
        assert!(err.problem.contains("same build"), "{err}");
    }

    #[test]
    fn a_sample_carries_its_priorities_once() {
        let mut b = TransitionBatch::new(
            ObservationLayout::new("toy", 1, 1, 2, 0),
            2,
            ObservationEncoding::SparseF32,
        );
        let o = b.push_observation(&[0.0, 1.0]);
        for priority in [0.5, 2.0] {
            b.push(Transition {
                observation: o,
                action: 0,
                reward: 0.0,
                discount: 1.0,
                priority,
                next_observation: o,
            });
        }
        let sample = Sample {
            keys: vec![7, 9],
            weights: vec![1.0, 0.5],
            batch: b.clone(),
        };
        let wire = sample_to_wire(sample);
        assert_eq!(wire.priorities, [0.5, 2.0], "the wire repeats them");
        let back = sample_from_wire(wire.clone()).expect("valid");
        assert_eq!((back.keys, back.weights), (vec![7, 9], vec![1.0, 0.5]));
        assert_eq!(back.batch.into_inner(), b);

        let mut short = wire;
        short.weights.pop();
        let err = sample_from_wire(short).expect_err("a weight short");
        assert_eq!(
            err.to_string(),
            "keys: 2 keys, 1 weights, 2 priorities for 2 transitions"
        );
    }
}
