//! The six per-transition columns, struct-of-arrays, written once for every
//! place that holds transitions: a [`TransitionBatch`](crate::TransitionBatch),
//! a replay table's ring, a table's snapshot image, a sample.
//!
//! [`Columns::write_le`] and [`Columns::read_le`] are the columns' bytes,
//! little-endian, in shared-memory frames and in snapshots.

use crate::batch::{BatchError, RejectReason, Transition};

/// Bytes of one row in [`Columns::write_le`]'s layout: six 4-byte values.
pub const ROW_BYTES: usize = 24;

/// The columns of transitions: entry `i` of every column belongs to
/// transition `i`. The two index columns refer to observations held beside
/// the columns (a batch's pool, a table's store, a snapshot's list); what
/// they index is the holder's to say.
///
/// Plain data: the columns may differ in length until checked
/// ([`check_lengths`](Self::check_lengths)); every method that reads rows
/// says what it does when they do.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Columns {
    /// Action taken.
    pub actions: Vec<u32>,
    /// Discounted reward summed over the transition's steps.
    pub rewards: Vec<f32>,
    /// Bootstrap discount gamma^k (0 when the episode ended).
    pub discounts: Vec<f32>,
    /// Priority, >= 0.
    pub priorities: Vec<f32>,
    /// Observation index of the state.
    pub observation_index: Vec<u32>,
    /// Observation index of the next state.
    pub next_observation_index: Vec<u32>,
}

// The per-row methods are `#[inline]`: the replay table calls them per item
// from another crate.
impl Columns {
    /// Empty columns with room for `n` rows each.
    pub fn with_capacity(n: usize) -> Self {
        Self {
            actions: Vec::with_capacity(n),
            rewards: Vec::with_capacity(n),
            discounts: Vec::with_capacity(n),
            priorities: Vec::with_capacity(n),
            observation_index: Vec::with_capacity(n),
            next_observation_index: Vec::with_capacity(n),
        }
    }

    /// Number of rows: the length of `actions`.
    #[inline]
    pub fn len(&self) -> usize {
        self.actions.len()
    }

    /// Whether there are no rows.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }

    /// Appends a row.
    #[inline]
    pub fn push(&mut self, t: Transition) {
        self.actions.push(t.action);
        self.rewards.push(t.reward);
        self.discounts.push(t.discount);
        self.priorities.push(t.priority);
        self.observation_index.push(t.observation);
        self.next_observation_index.push(t.next_observation);
    }

    /// Row `i`, if every column has it.
    #[inline]
    pub fn get(&self, i: usize) -> Option<Transition> {
        Some(Transition {
            observation: *self.observation_index.get(i)?,
            action: *self.actions.get(i)?,
            reward: *self.rewards.get(i)?,
            discount: *self.discounts.get(i)?,
            priority: *self.priorities.get(i)?,
            next_observation: *self.next_observation_index.get(i)?,
        })
    }

    /// Overwrites row `i`. Panics if a column is shorter than `i + 1`.
    #[inline]
    pub fn set(&mut self, i: usize, t: Transition) {
        self.actions[i] = t.action;
        self.rewards[i] = t.reward;
        self.discounts[i] = t.discount;
        self.priorities[i] = t.priority;
        self.observation_index[i] = t.observation;
        self.next_observation_index[i] = t.next_observation;
    }

    /// The rows at `rows`, in that order (repeats allowed). Panics if a row
    /// is out of range of a column.
    pub fn gather(&self, rows: &[usize]) -> Self {
        let pick = |column: &[u32]| rows.iter().map(|r| column[*r]).collect();
        let pick_f32 = |column: &[f32]| rows.iter().map(|r| column[*r]).collect();
        Self {
            actions: pick(&self.actions),
            rewards: pick_f32(&self.rewards),
            discounts: pick_f32(&self.discounts),
            priorities: pick_f32(&self.priorities),
            observation_index: pick(&self.observation_index),
            next_observation_index: pick(&self.next_observation_index),
        }
    }

    /// Checks that every column has as many entries as `actions`; the
    /// error names the first column that does not.
    pub fn check_lengths(&self) -> Result<(), BatchError> {
        let n = self.len();
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
        Ok(())
    }

    /// Bytes of [`write_le`](Self::write_le)'s layout: [`ROW_BYTES`] per
    /// row.
    pub fn byte_len(&self) -> usize {
        ROW_BYTES * self.len()
    }

    /// Bytes the columns' buffers hold (their capacity, not their length).
    pub fn capacity_bytes(&self) -> usize {
        4 * (self.actions.capacity()
            + self.rewards.capacity()
            + self.discounts.capacity()
            + self.priorities.capacity()
            + self.observation_index.capacity()
            + self.next_observation_index.capacity())
    }

    /// Writes the columns one after another, each value as 4 little-endian
    /// bytes, in the order of the fields; `out` is exactly
    /// [`byte_len`](Self::byte_len) bytes. The layout of the shared-memory batch
    /// frame and of replay snapshots: changing it changes both formats.
    /// Panics if `out` has another size or the columns differ in length.
    pub fn write_le(&self, out: &mut [u8]) {
        assert_eq!(out.len(), self.byte_len(), "columns' byte size");
        let mut words = out.chunks_exact_mut(4);
        let mut put = |bytes: [u8; 4]| {
            if let Some(w) = words.next() {
                w.copy_from_slice(&bytes);
            }
        };
        self.actions.iter().for_each(|v| put(v.to_le_bytes()));
        for column in [&self.rewards, &self.discounts, &self.priorities] {
            column.iter().for_each(|v| put(v.to_le_bytes()));
        }
        for column in [&self.observation_index, &self.next_observation_index] {
            column.iter().for_each(|v| put(v.to_le_bytes()));
        }
        assert!(words.next().is_none(), "columns of equal length");
    }

    /// Reads what [`write_le`](Self::write_le) wrote; `None` unless
    /// `bytes` is a whole number of rows.
    pub fn read_le(bytes: &[u8]) -> Option<Self> {
        if !bytes.len().is_multiple_of(ROW_BYTES) {
            return None;
        }
        let n = bytes.len() / ROW_BYTES;
        let column = |k: usize| {
            bytes[4 * n * k..4 * n * (k + 1)]
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]])
        };
        let u32s = |k| column(k).map(u32::from_le_bytes).collect();
        let f32s = |k| column(k).map(f32::from_le_bytes).collect();
        Some(Self {
            actions: u32s(0),
            rewards: f32s(1),
            discounts: f32s(2),
            priorities: f32s(3),
            observation_index: u32s(4),
            next_observation_index: u32s(5),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(k: u32) -> Transition {
        Transition {
            observation: 10 + k,
            action: k,
            reward: -(k as f32),
            discount: 0.5,
            priority: 2.0 * k as f32,
            next_observation: 20 + k,
        }
    }

    #[test]
    fn rows_in_and_out() {
        let mut c = Columns::with_capacity(3);
        (0..3).for_each(|k| c.push(row(k)));
        assert_eq!((c.len(), c.get(2), c.get(3)), (3, Some(row(2)), None));
        c.set(0, row(7));
        assert_eq!(c.get(0), Some(row(7)));
        let g = c.gather(&[2, 2, 0]);
        assert_eq!(
            (0..3).filter_map(|i| g.get(i)).collect::<Vec<_>>(),
            [row(2), row(2), row(7)]
        );
        assert_eq!(c.check_lengths(), Ok(()));
        c.discounts.pop();
        let err = c.check_lengths().expect_err("short column");
        assert_eq!(
            (err.reason, err.field.as_str()),
            (RejectReason::LengthMismatch, "discounts")
        );
        assert_eq!(err.problem, "has 2 entries, but there are 3 actions");
        assert_eq!(c.get(2), None, "a row missing from one column");
    }

    #[test]
    fn little_endian_round_trip() {
        let mut c = Columns::default();
        (0..4).for_each(|k| c.push(row(k)));
        let mut bytes = vec![0; ROW_BYTES * 4];
        c.write_le(&mut bytes);
        // Column-major: the four actions first, then the four rewards.
        assert_eq!(&bytes[..8], &[0, 0, 0, 0, 1, 0, 0, 0]);
        assert_eq!(&bytes[20..24], &(-1f32).to_le_bytes());
        assert_eq!(Columns::read_le(&bytes), Some(c));
        assert_eq!(Columns::read_le(&bytes[1..]), None);
        assert_eq!(Columns::read_le(&[]), Some(Columns::default()));
    }
}
