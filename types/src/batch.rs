//! The domain transition batch: n-step transitions as struct-of-arrays, with
//! an observation pool that holds each observation once.
//!
//! [`TransitionBatch`] is what actors build ([`TransitionBatch::push`]) and
//! transports carry (converted to the wire in `crossroads_transport::wire`
//! and `crossroads_transport::shm`); its [`Columns`] are the six
//! per-transition columns. [`ValidBatch`] is a batch that passed
//! [`TransitionBatch::validate`], the one check: made where a batch enters
//! a process, it is what the replay server stores and the learner trains
//! on, never checked again. A [`BatchError`] names the offending field and
//! carries a [`RejectReason`] for counters.

use std::fmt;

use crate::codec::{self, CodecError, ObservationEncoding};
use crate::columns::Columns;
use crate::spec::ObservationLayout;

/// Largest observation accepted, in values (a guard against shapes whose
/// product overflows or exhausts memory).
pub const MAX_OBSERVATION_LEN: usize = 1 << 24;

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

/// A batch of n-step transitions, struct-of-arrays: row `i` of the
/// [`Columns`] is transition `i`, its index columns refer to entries of the
/// [`ObservationPool`].
///
/// What an actor builds and a transport reads, unchecked: nothing here
/// trusts it. [`ValidBatch::new`] checks it once, and a [`ValidBatch`] is
/// what receivers keep.
#[derive(Debug, Clone, PartialEq)]
pub struct TransitionBatch {
    /// What each observation is.
    pub layout: ObservationLayout,
    /// Size of the action set; every action is below it.
    pub num_actions: u32,
    /// The transitions; the index columns refer to `observations`.
    pub columns: Columns,
    /// The observations, each once.
    pub observations: ObservationPool,
}

impl TransitionBatch {
    /// An empty batch.
    pub fn new(layout: ObservationLayout, num_actions: u32, encoding: ObservationEncoding) -> Self {
        Self {
            layout,
            num_actions,
            columns: Columns::default(),
            observations: ObservationPool::new(encoding),
        }
    }

    /// Adds an observation (values in the layout's order); returns
    /// its pool index for [`Transition`]s.
    pub fn push_observation(&mut self, values: &[f32]) -> u32 {
        self.observations.push_values(values)
    }

    /// Adds a transition.
    pub fn push(&mut self, t: Transition) {
        self.columns.push(t);
    }

    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.columns.len()
    }

    /// Whether the batch has no transitions.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }

    /// Transition `i`, if there is one.
    pub fn transition(&self, i: usize) -> Option<Transition> {
        self.columns.get(i)
    }

    /// Checks everything a receiver relies on: a valid layout
    /// ([`ObservationLayout::check`]), equal column lengths, finite
    /// rewards, discounts in [0, 1], finite non-negative priorities,
    /// actions below `num_actions`, pool indices in range and every
    /// observation entry valid for the layout's length. The first
    /// problem found is returned, naming its field. [`ValidBatch::new`] is
    /// this check with a type for its success.
    pub fn validate(&self) -> Result<(), BatchError> {
        let obs_len = self
            .layout
            .check()
            .map_err(|problem| BatchError::new(RejectReason::Spec, "layout", problem))?;
        if self.num_actions == 0 {
            return Err(BatchError::new(
                RejectReason::Spec,
                "num_actions",
                "must be at least 1",
            ));
        }
        let c = &self.columns;
        if c.is_empty() {
            return Err(BatchError::new(
                RejectReason::EmptyBatch,
                "actions",
                "the batch has no transitions",
            ));
        }
        c.check_lengths()?;
        for (i, a) in c.actions.iter().enumerate() {
            if *a >= self.num_actions {
                return Err(BatchError::new(
                    RejectReason::ActionRange,
                    format!("actions[{i}]"),
                    format!("{a} is not below num_actions {}", self.num_actions),
                ));
            }
        }
        for (i, r) in c.rewards.iter().enumerate() {
            if !r.is_finite() {
                return Err(BatchError::new(
                    RejectReason::NonFiniteReward,
                    format!("rewards[{i}]"),
                    format!("{r} is not finite"),
                ));
            }
        }
        for (i, d) in c.discounts.iter().enumerate() {
            if !(0.0..=1.0).contains(d) {
                return Err(BatchError::new(
                    RejectReason::Discount,
                    format!("discounts[{i}]"),
                    format!("{d} is not in [0, 1]"),
                ));
            }
        }
        check_priorities(&c.priorities, |i| format!("priorities[{i}]"))?;
        let pool = &self.observations;
        for (field, indices) in [
            ("observation_index", &c.observation_index),
            ("next_observation_index", &c.next_observation_index),
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
                    format!("{e} (layout {})", self.layout),
                )
            })?;
        }
        Ok(())
    }
}

/// A [`TransitionBatch`] that passed [`TransitionBatch::validate`]. Made
/// only by [`ValidBatch::new`] (or `TryFrom`) and read-only after (it
/// dereferences to the batch), so whoever holds one never checks it again:
/// a batch is checked once where it enters a process, and passed on as
/// this type.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidBatch(TransitionBatch);

impl ValidBatch {
    /// `batch`, if it validates; otherwise the first problem, naming its
    /// field.
    pub fn new(batch: TransitionBatch) -> Result<Self, BatchError> {
        batch.validate()?;
        Ok(Self(batch))
    }

    /// The batch, to change or take apart (it is no longer known valid).
    pub fn into_inner(self) -> TransitionBatch {
        self.0
    }
}

impl std::ops::Deref for ValidBatch {
    type Target = TransitionBatch;

    fn deref(&self) -> &TransitionBatch {
        &self.0
    }
}

impl TryFrom<TransitionBatch> for ValidBatch {
    type Error = BatchError;

    fn try_from(batch: TransitionBatch) -> Result<Self, BatchError> {
        Self::new(batch)
    }
}

/// Checks priorities: each finite and >= 0. The error names the first bad
/// one as `field(i)` says (e.g. `priorities[3]`).
pub fn check_priorities(
    priorities: &[f32],
    field: impl Fn(usize) -> String,
) -> Result<(), BatchError> {
    for (i, p) in priorities.iter().enumerate() {
        let problem = if !p.is_finite() {
            (
                RejectReason::NonFinitePriority,
                format!("{p} is not finite"),
            )
        } else if *p < 0.0 {
            (RejectReason::NegativePriority, format!("{p} is negative"))
        } else {
            continue;
        };
        return Err(BatchError::new(problem.0, field(i), problem.1));
    }
    Ok(())
}

/// Why an input was rejected; the label of the rejection counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RejectReason {
    /// Observation layout or action count invalid, or not the table's.
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
    /// An observation whose byte length does not match the layout.
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
    /// Well formed, but the server could not store it durably now (its
    /// write-ahead log failed; a full disk, say): nothing acknowledged,
    /// worth sending again later.
    Unavailable,
}

impl RejectReason {
    /// Every reason, for pre-registering counters.
    pub const ALL: [RejectReason; 16] = [
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
        RejectReason::Unavailable,
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
            RejectReason::Unavailable => "unavailable",
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
    use crate::codec::ObservationEncoding::DenseF32;

    fn batch() -> TransitionBatch {
        let mut b = TransitionBatch::new(
            ObservationLayout::new("toy", 1, 2, 3, 0),
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
        assert_eq!(
            ValidBatch::new(batch()).map(ValidBatch::into_inner),
            Ok(batch())
        );
    }

    fn rejects(mutate: impl FnOnce(&mut TransitionBatch), reason: RejectReason, field: &str) {
        let mut b = batch();
        mutate(&mut b);
        let err = ValidBatch::new(b).expect_err(field);
        assert_eq!((err.reason, err.field.as_str()), (reason, field), "{err}");
    }

    #[test]
    fn each_problem_names_its_field() {
        use RejectReason::*;
        // Each bad value as a change to transition 0.
        type Change = fn(&mut Transition);
        let rows: [(Change, RejectReason, &str); 6] = [
            (|t| t.action = 4, ActionRange, "actions[0]"),
            (|t| t.reward = f32::NAN, NonFiniteReward, "rewards[0]"),
            (|t| t.discount = 1.5, Discount, "discounts[0]"),
            (|t| t.priority = -1.0, NegativePriority, "priorities[0]"),
            (
                |t| t.priority = f32::INFINITY,
                NonFinitePriority,
                "priorities[0]",
            ),
            (
                |t| t.next_observation = 2,
                IndexRange,
                "next_observation_index[0]",
            ),
        ];
        for (change, reason, field) in rows {
            let set_row = |b: &mut TransitionBatch| {
                let mut t = b.transition(0).expect("one transition");
                change(&mut t);
                b.columns.set(0, t);
            };
            rejects(set_row, reason, field);
        }
        rejects(|b| b.columns.rewards.push(0.0), LengthMismatch, "rewards");
        rejects(
            |b| b.layout.cols = 2,
            ObservationEncoding,
            "observations[0]",
        );
        let dense_short = |b: &mut TransitionBatch| {
            let data = vec![0; 44];
            b.observations = ObservationPool::from_parts(DenseF32, vec![0, 24], data);
        };
        rejects(dense_short, ObservationLength, "observations[1]");
        rejects(|b| b.layout.rows = 0, Spec, "layout");
        rejects(|b| b.layout.kind.clear(), Spec, "layout");
    }

    #[test]
    fn priorities_are_finite_and_not_negative() {
        let field = |i| format!("p[{i}]");
        assert_eq!(check_priorities(&[0.0, 2.5], field), Ok(()));
        let err = check_priorities(&[1.0, f32::NAN, -1.0], field).expect_err("NaN");
        assert_eq!(err.to_string(), "p[1]: NaN is not finite");
        let err = check_priorities(&[-0.5], field).expect_err("negative");
        assert_eq!(
            (err.reason, err.problem.as_str()),
            (RejectReason::NegativePriority, "-0.5 is negative")
        );
    }

    #[test]
    fn layout_len_guards_overflow() {
        let huge = i64::from(u32::MAX);
        rejects(
            |b| b.layout = ObservationLayout::new("x", huge, huge, huge, 0),
            RejectReason::Spec,
            "layout",
        );
        let err = ValidBatch::new({
            let mut b = batch();
            b.layout.extra = -1;
            b
        })
        .expect_err("negative extra");
        assert!(err.problem.contains("toy [1x2x3 + -1]"), "{err}");
    }
}
