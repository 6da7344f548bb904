//! A table's whole content as snapshots and the write-ahead log store it,
//! and the check an image must pass before a table takes it in.

use crossroads_types::batch::{BatchError, RejectReason, Transition, TransitionBatch};
use crossroads_types::{Columns, ObservationEncoding, ObservationLayout};

/// A table's whole content in FIFO order, for snapshots.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TableImage {
    /// Observation layout and action count the table holds, if it got a
    /// batch (a legacy layout, [`ObservationLayout::legacy`], when read
    /// from a file of an earlier build).
    pub spec: Option<(ObservationLayout, u32)>,
    /// Key the next insert gets; the items hold keys
    /// `next_key - len .. next_key`.
    pub next_key: u64,
    /// Items ever inserted (the rate limiter's count).
    pub inserts_total: u64,
    /// Items ever sampled (the rate limiter's count).
    pub samples_total: u64,
    /// Priority updates.
    pub priority_updates_total: u64,
    /// Ignored priority updates.
    pub ignored_updates_total: u64,
    /// The items, oldest first, with their raw priorities; the index
    /// columns refer to the observations below.
    pub items: Columns,
    /// Start of each compact observation in `observation_data`.
    pub observation_offsets: Vec<u64>,
    /// Compact observations back to back.
    pub observation_data: Vec<u8>,
}

impl TableImage {
    /// Items in the image.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether it holds no item.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// The compact bytes of observation `i`, if the offsets hold it.
    pub(crate) fn observation(&self, i: usize) -> Option<&[u8]> {
        let start = *self.observation_offsets.get(i)? as usize;
        let end = self
            .observation_offsets
            .get(i + 1)
            .map_or(self.observation_data.len(), |e| *e as usize);
        self.observation_data.get(start..end)
    }
}

/// Checks what a snapshot's image says of its items, as
/// [`TransitionBatch::validate`] checks a batch's: returns the length of
/// an observation (each is checked as it is stored).
pub(crate) fn check_image(image: &TableImage) -> Result<usize, BatchError> {
    let c = &image.items;
    let n = c.len();
    if c.check_lengths().is_err() || image.next_key < n as u64 {
        return Err(BatchError::new(
            RejectReason::LengthMismatch,
            "items",
            "columns of different lengths",
        ));
    }
    let Some((layout, num_actions)) = &image.spec else {
        if n == 0 {
            return Ok(0);
        }
        return Err(BatchError::new(
            RejectReason::Spec,
            "layout",
            format!("{n} items without a layout"),
        ));
    };
    let obs_len = layout
        .check()
        .ok()
        .filter(|_| *num_actions > 0)
        .ok_or_else(|| {
            BatchError::new(
                RejectReason::Spec,
                "layout",
                format!("{layout} with {num_actions} actions is not a valid layout"),
            )
        })?;
    // One transition at a time, through the batch check.
    let mut one =
        TransitionBatch::new(layout.clone(), *num_actions, ObservationEncoding::SparseF32);
    one.push_observation(&[]);
    one.push(Transition {
        observation: 0,
        action: 0,
        reward: 0.0,
        discount: 0.0,
        priority: 0.0,
        next_observation: 0,
    });
    for i in 0..n {
        let Some(t) = c.get(i) else { break };
        one.columns.set(
            0,
            Transition {
                observation: 0,
                next_observation: 0,
                ..t
            },
        );
        one.validate().map_err(|e| {
            let field = e.field.replacen("[0]", &format!("[{i}]"), 1);
            BatchError::new(e.reason, format!("items.{field}"), e.problem)
        })?;
    }
    let n_obs = image.observation_offsets.len();
    for (i, (o, no)) in c
        .observation_index
        .iter()
        .zip(&c.next_observation_index)
        .enumerate()
    {
        if *o as usize >= n_obs || *no as usize >= n_obs {
            return Err(BatchError::new(
                RejectReason::IndexRange,
                format!("items[{i}].observation"),
                format!("refers to observation {} of {n_obs}", (*o).max(*no)),
            ));
        }
    }
    Ok(obs_len)
}
