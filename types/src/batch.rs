//! The domain transition batch: n-step transitions as struct-of-arrays, with
//! an observation pool that holds each observation once.
//!
//! [`TransitionBatch`] is what actors build ([`TransitionBatch::push`]),
//! transports carry (converted to the wire in `crossroads_transport::wire`
//! and `crossroads_transport::shm`) and the replay server stores. Its
//! [`TransitionBatch::validate`] is the one check applied at every boundary;
//! a [`BatchError`] names the offending field and carries a
//! [`RejectReason`] for counters.

use std::fmt;

use crate::codec::{self, CodecError, ObservationEncoding};

/// Largest observation accepted, in values (a guard against shapes whose
/// product overflows or exhausts memory).
pub const MAX_OBSERVATION_LEN: usize = 1 << 24;

/// What one observation is: the simulator view and its row-major shape.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ObservationSpec {
    /// Simulator view, e.g. `ttg`.
    pub kind: String,
    /// Row-major dimensions, e.g. `[18, 26, 5]`.
    pub shape: Vec<u32>,
}

impl ObservationSpec {
    /// A spec of `kind` and `shape`.
    pub fn new(kind: impl Into<String>, shape: impl Into<Vec<u32>>) -> Self {
        Self {
            kind: kind.into(),
            shape: shape.into(),
        }
    }

    /// The time-to-go grid: 18 x 26 cells, 5 channels (occupancy, heading,
    /// speed, x and y offset in the cell).
    pub fn ttg() -> Self {
        Self::new("ttg", [18, 26, 5])
    }

    /// Number of values of one observation; `None` if the shape is empty or
    /// larger than [`MAX_OBSERVATION_LEN`].
    pub fn num_values(&self) -> Option<usize> {
        if self.shape.is_empty() {
            return None;
        }
        self.shape
            .iter()
            .try_fold(1usize, |acc, d| acc.checked_mul(*d as usize))
            .filter(|n| (1..=MAX_OBSERVATION_LEN).contains(n))
    }
}

impl fmt::Display for ObservationSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let dims: Vec<String> = self.shape.iter().map(ToString::to_string).collect();
        write!(f, "{} [{}]", self.kind, dims.join("x"))
    }
}

/// Encoded observations; transitions refer to entries by index.
#[derive(Debug, Clone, PartialEq)]
pub struct ObservationPool {
    encoding: ObservationEncoding,
    offsets: Vec<u32>,
    data: Vec<u8>,
}

impl ObservationPool {
    /// An empty pool.
    pub fn new(encoding: ObservationEncoding) -> Self {
        Self {
            encoding,
            offsets: Vec::new(),
            data: Vec::new(),
        }
    }

    /// A pool from its parts as they travel: entry `i` spans
    /// `data[offsets[i]..offsets[i + 1]]` (or to the end for the last).
    /// Not checked here; see [`TransitionBatch::validate`].
    pub fn from_parts(encoding: ObservationEncoding, offsets: Vec<u32>, data: Vec<u8>) -> Self {
        Self {
            encoding,
            offsets,
            data,
        }
    }

    /// The encoding of every entry.
    pub fn encoding(&self) -> ObservationEncoding {
        self.encoding
    }

    /// Start offsets of the entries.
    pub fn offsets(&self) -> &[u32] {
        &self.offsets
    }

    /// The encoded bytes of every entry, back to back.
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// The parts, for transports.
    pub fn into_parts(self) -> (ObservationEncoding, Vec<u32>, Vec<u8>) {
        (self.encoding, self.offsets, self.data)
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.offsets.len()
    }

    /// Whether the pool has no entries.
    pub fn is_empty(&self) -> bool {
        self.offsets.is_empty()
    }

    /// Appends an observation given as values, encoding it; returns its
    /// index.
    pub fn push_values(&mut self, values: &[f32]) -> u32 {
        let index = self.offsets.len() as u32;
        self.offsets.push(self.data.len() as u32);
        codec::encode(self.encoding, values, &mut self.data);
        index
    }

    /// Appends an already encoded observation; returns its index.
    pub fn push_encoded(&mut self, bytes: &[u8]) -> u32 {
        let index = self.offsets.len() as u32;
        self.offsets.push(self.data.len() as u32);
        self.data.extend_from_slice(bytes);
        index
    }

    /// The bytes of entry `i`, if the offsets are consistent.
    pub fn get(&self, i: usize) -> Option<&[u8]> {
        let start = *self.offsets.get(i)? as usize;
        let end = match self.offsets.get(i + 1) {
            Some(end) => *end as usize,
            None => self.data.len(),
        };
        self.data.get(start..end)
    }

    /// Decodes entry `i` into `out` (the observation's length).
    pub fn decode_into(&self, i: usize, out: &mut [f32]) -> Result<(), CodecError> {
        let bytes = self.get(i).ok_or(CodecError::Length {
            expected: "an entry".to_owned(),
            got: 0,
        })?;
        codec::decode_into(self.encoding, bytes, out)
    }
}

/// One transition as an actor hands it over, referring to observations
/// already pushed into the batch's pool.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// Pool index of the state.
    pub observation: u32,
    /// Action taken.
    pub action: u32,
    /// Discounted reward summed over the transition's steps.
    pub reward: f32,
    /// Bootstrap discount gamma^k; 0 when the episode ended.
    pub discount: f32,
    /// Initial priority, >= 0.
    pub priority: f32,
    /// Pool index of the next state.
    pub next_observation: u32,
}

/// A batch of n-step transitions, struct-of-arrays: entry `i` of every
/// column belongs to transition `i`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransitionBatch {
    /// What each observation is.
    pub spec: ObservationSpec,
    /// Size of the action set; every action is below it.
    pub num_actions: u32,
    /// Action taken, per transition.
    pub actions: Vec<u32>,
    /// Discounted reward, per transition.
    pub rewards: Vec<f32>,
    /// Bootstrap discount gamma^k (0 when terminal), per transition.
    pub discounts: Vec<f32>,
    /// Initial priority, per transition.
    pub priorities: Vec<f32>,
    /// The observations, each once.
    pub observations: ObservationPool,
    /// Pool index of each transition's state.
    pub observation_index: Vec<u32>,
    /// Pool index of each transition's next state.
    pub next_observation_index: Vec<u32>,
}

impl TransitionBatch {
    /// An empty batch.
    pub fn new(spec: ObservationSpec, num_actions: u32, encoding: ObservationEncoding) -> Self {
        Self {
            spec,
            num_actions,
            actions: Vec::new(),
            rewards: Vec::new(),
            discounts: Vec::new(),
            priorities: Vec::new(),
            observations: ObservationPool::new(encoding),
            observation_index: Vec::new(),
            next_observation_index: Vec::new(),
        }
    }

    /// Adds an observation (values in the spec's row-major order); returns
    /// its pool index for [`Transition`]s.
    pub fn push_observation(&mut self, values: &[f32]) -> u32 {
        self.observations.push_values(values)
    }

    /// Adds a transition.
    pub fn push(&mut self, t: Transition) {
        self.actions.push(t.action);
        self.rewards.push(t.reward);
        self.discounts.push(t.discount);
        self.priorities.push(t.priority);
        self.observation_index.push(t.observation);
        self.next_observation_index.push(t.next_observation);
    }

    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.actions.len()
    }

    /// Whether the batch has no transitions.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }

    /// Transition `i`, if there is one.
    pub fn transition(&self, i: usize) -> Option<Transition> {
        Some(Transition {
            observation: *self.observation_index.get(i)?,
            action: *self.actions.get(i)?,
            reward: *self.rewards.get(i)?,
            discount: *self.discounts.get(i)?,
            priority: *self.priorities.get(i)?,
            next_observation: *self.next_observation_index.get(i)?,
        })
    }

    /// Checks everything a receiver relies on: a known spec, equal column
    /// lengths, finite rewards, discounts in [0, 1], finite non-negative
    /// priorities, actions below `num_actions`, pool indices in range and
    /// every observation entry valid for the spec's length. The first
    /// problem found is returned, naming its field.
    pub fn validate(&self) -> Result<(), BatchError> {
        let obs_len = self.spec.num_values().ok_or_else(|| {
            BatchError::new(
                RejectReason::Spec,
                "spec.shape",
                format!(
                    "must be non-empty with at most {MAX_OBSERVATION_LEN} values, got {:?}",
                    self.spec.shape
                ),
            )
        })?;
        if self.spec.kind.is_empty() {
            return Err(BatchError::new(
                RejectReason::Spec,
                "spec.kind",
                "must not be empty",
            ));
        }
        if self.num_actions == 0 {
            return Err(BatchError::new(
                RejectReason::Spec,
                "num_actions",
                "must be at least 1",
            ));
        }
        let n = self.len();
        if n == 0 {
            return Err(BatchError::new(
                RejectReason::EmptyBatch,
                "actions",
                "the batch has no transitions",
            ));
        }
        for (field, len) in [
            ("rewards", self.rewards.len()),
            ("discounts", self.discounts.len()),
            ("priorities", self.priorities.len()),
            ("observation_index", self.observation_index.len()),
            ("next_observation_index", self.next_observation_index.len()),
        ] {
            if len != n {
                return Err(BatchError::new(
                    RejectReason::LengthMismatch,
                    field,
                    format!("has {len} entries, but there are {n} actions"),
                ));
            }
        }
        for (i, a) in self.actions.iter().enumerate() {
            if *a >= self.num_actions {
                return Err(BatchError::new(
                    RejectReason::ActionRange,
                    format!("actions[{i}]"),
                    format!("{a} is not below num_actions {}", self.num_actions),
                ));
            }
        }
        for (i, r) in self.rewards.iter().enumerate() {
            if !r.is_finite() {
                return Err(BatchError::new(
                    RejectReason::NonFiniteReward,
                    format!("rewards[{i}]"),
                    format!("{r} is not finite"),
                ));
            }
        }
        for (i, d) in self.discounts.iter().enumerate() {
            if !(0.0..=1.0).contains(d) {
                return Err(BatchError::new(
                    RejectReason::Discount,
                    format!("discounts[{i}]"),
                    format!("{d} is not in [0, 1]"),
                ));
            }
        }
        for (i, p) in self.priorities.iter().enumerate() {
            check_priority(*p).map_err(|(reason, problem)| {
                BatchError::new(reason, format!("priorities[{i}]"), problem)
            })?;
        }
        let pool = &self.observations;
        for (field, indices) in [
            ("observation_index", &self.observation_index),
            ("next_observation_index", &self.next_observation_index),
        ] {
            for (i, idx) in indices.iter().enumerate() {
                if *idx as usize >= pool.len() {
                    return Err(BatchError::new(
                        RejectReason::IndexRange,
                        format!("{field}[{i}]"),
                        format!("{idx} is not below the pool's {} entries", pool.len()),
                    ));
                }
            }
        }
        let mut previous = 0u32;
        for (i, off) in pool.offsets.iter().enumerate() {
            if *off < previous || *off as usize > pool.data.len() {
                return Err(BatchError::new(
                    RejectReason::ObservationEncoding,
                    format!("observations.offsets[{i}]"),
                    format!(
                        "{off} is not between the previous offset {previous} and the data length {}",
                        pool.data.len()
                    ),
                ));
            }
            previous = *off;
        }
        if pool.offsets.first().is_some_and(|o| *o != 0) {
            return Err(BatchError::new(
                RejectReason::ObservationEncoding,
                "observations.offsets[0]",
                "must be 0",
            ));
        }
        for i in 0..pool.len() {
            let bytes = pool.get(i).unwrap_or_default();
            codec::check(pool.encoding, bytes, obs_len).map_err(|e| {
                let reason = match e {
                    CodecError::NonFinite { .. } => RejectReason::NonFiniteObservation,
                    CodecError::Length { .. } => RejectReason::ObservationLength,
                    CodecError::IndexRange { .. } | CodecError::IndexOrder { .. } => {
                        RejectReason::ObservationEncoding
                    }
                };
                BatchError::new(
                    reason,
                    format!("observations[{i}]"),
                    format!("{e} (spec {})", self.spec),
                )
            })?;
        }
        Ok(())
    }
}

/// Checks one priority: finite and >= 0.
pub fn check_priority(p: f32) -> Result<(), (RejectReason, String)> {
    if !p.is_finite() {
        Err((
            RejectReason::NonFinitePriority,
            format!("{p} is not finite"),
        ))
    } else if p < 0.0 {
        Err((RejectReason::NegativePriority, format!("{p} is negative")))
    } else {
        Ok(())
    }
}

/// Why an input was rejected; the label of the rejection counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RejectReason {
    /// Observation kind, shape or action count missing, or not the table's.
    Spec,
    /// A batch without transitions.
    EmptyBatch,
    /// Columns of different lengths.
    LengthMismatch,
    /// An action not below `num_actions`.
    ActionRange,
    /// A NaN or infinite reward.
    NonFiniteReward,
    /// A discount outside [0, 1] or NaN.
    Discount,
    /// A NaN or infinite priority.
    NonFinitePriority,
    /// A priority below zero.
    NegativePriority,
    /// An observation index outside the pool.
    IndexRange,
    /// An observation whose byte length does not match the spec.
    ObservationLength,
    /// Bad offsets, an unknown encoding, or sparse indices out of range or
    /// order.
    ObservationEncoding,
    /// A NaN or infinite observation value.
    NonFiniteObservation,
    /// A message, batch or request larger than the server accepts.
    Oversized,
    /// A table name the server does not have.
    UnknownTable,
    /// Another malformed request field (batch size 0, beta outside [0, 1],
    /// keys and priorities of different lengths, a missing batch).
    BadRequest,
}

impl RejectReason {
    /// Every reason, for pre-registering counters.
    pub const ALL: [RejectReason; 15] = [
        RejectReason::Spec,
        RejectReason::EmptyBatch,
        RejectReason::LengthMismatch,
        RejectReason::ActionRange,
        RejectReason::NonFiniteReward,
        RejectReason::Discount,
        RejectReason::NonFinitePriority,
        RejectReason::NegativePriority,
        RejectReason::IndexRange,
        RejectReason::ObservationLength,
        RejectReason::ObservationEncoding,
        RejectReason::NonFiniteObservation,
        RejectReason::Oversized,
        RejectReason::UnknownTable,
        RejectReason::BadRequest,
    ];

    /// The counter label, e.g. `non_finite_reward`.
    pub fn as_str(self) -> &'static str {
        match self {
            RejectReason::Spec => "spec",
            RejectReason::EmptyBatch => "empty_batch",
            RejectReason::LengthMismatch => "length_mismatch",
            RejectReason::ActionRange => "action_range",
            RejectReason::NonFiniteReward => "non_finite_reward",
            RejectReason::Discount => "discount",
            RejectReason::NonFinitePriority => "non_finite_priority",
            RejectReason::NegativePriority => "negative_priority",
            RejectReason::IndexRange => "index_range",
            RejectReason::ObservationLength => "observation_length",
            RejectReason::ObservationEncoding => "observation_encoding",
            RejectReason::NonFiniteObservation => "non_finite_observation",
            RejectReason::Oversized => "oversized",
            RejectReason::UnknownTable => "unknown_table",
            RejectReason::BadRequest => "bad_request",
        }
    }
}

impl fmt::Display for RejectReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An input rejected at a boundary: which field, why, and the reason label.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {problem}")]
pub struct BatchError {
    /// The reason, for counters and for matching.
    pub reason: RejectReason,
    /// The offending field, e.g. `rewards[3]` or `observations[0]`.
    pub field: String,
    /// What is wrong with it.
    pub problem: String,
}

impl BatchError {
    /// An error about `field`.
    pub fn new(reason: RejectReason, field: impl Into<String>, problem: impl Into<String>) -> Self {
        Self {
            reason,
            field: field.into(),
            problem: problem.into(),
        }
    }

    /// The same error with `prefix.` before the field (e.g. `batch.`).
    pub fn within(mut self, prefix: &str) -> Self {
        self.field = format!("{prefix}.{}", self.field);
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch() -> TransitionBatch {
        let mut b = TransitionBatch::new(
            ObservationSpec::new("toy", [2, 3]),
            4,
            ObservationEncoding::SparseF32,
        );
        let o0 = b.push_observation(&[0.0, 1.0, 0.0, 0.0, 0.0, 2.0]);
        let o1 = b.push_observation(&[0.0; 6]);
        b.push(Transition {
            observation: o0,
            action: 3,
            reward: 1.0,
            discount: 0.9,
            priority: 0.5,
            next_observation: o1,
        });
        b
    }

    #[test]
    fn a_good_batch_validates() {
        assert_eq!(batch().validate(), Ok(()));
    }

    #[test]
    fn each_problem_names_its_field() {
        type Mutation = fn(&mut TransitionBatch);
        let cases: Vec<(Mutation, RejectReason, &str)> = vec![
            (
                |b| b.actions[0] = 4,
                RejectReason::ActionRange,
                "actions[0]",
            ),
            (
                |b| b.rewards[0] = f32::NAN,
                RejectReason::NonFiniteReward,
                "rewards[0]",
            ),
            (
                |b| b.discounts[0] = 1.5,
                RejectReason::Discount,
                "discounts[0]",
            ),
            (
                |b| b.priorities[0] = -1.0,
                RejectReason::NegativePriority,
                "priorities[0]",
            ),
            (
                |b| b.priorities[0] = f32::INFINITY,
                RejectReason::NonFinitePriority,
                "priorities[0]",
            ),
            (
                |b| b.next_observation_index[0] = 2,
                RejectReason::IndexRange,
                "next_observation_index[0]",
            ),
            (
                |b| b.rewards.push(0.0),
                RejectReason::LengthMismatch,
                "rewards",
            ),
            (
                |b| b.spec.shape = vec![2, 2],
                RejectReason::ObservationEncoding,
                "observations[0]",
            ),
            (
                |b| {
                    b.observations = ObservationPool::from_parts(
                        ObservationEncoding::DenseF32,
                        vec![0, 24],
                        vec![0; 44],
                    )
                },
                RejectReason::ObservationLength,
                "observations[1]",
            ),
            (|b| b.spec.shape = vec![], RejectReason::Spec, "spec.shape"),
        ];
        for (mutate, reason, field) in cases {
            let mut b = batch();
            mutate(&mut b);
            let err = b.validate().expect_err(field);
            assert_eq!((err.reason, err.field.as_str()), (reason, field), "{err}");
        }
    }

    #[test]
    fn spec_len_guards_overflow() {
        assert_eq!(ObservationSpec::ttg().num_values(), Some(2340));
        assert_eq!(
            ObservationSpec::new("x", [u32::MAX, u32::MAX]).num_values(),
            None
        );
        assert_eq!(ObservationSpec::new("x", [0]).num_values(), None);
    }
}
