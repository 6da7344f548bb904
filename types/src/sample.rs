//! What a replay table answers: a [`Sample`] of items, and what a priority
//! update did ([`PrioritiesUpdated`]). The replay server makes them and its
//! clients receive them, so both speak these types.

use crate::batch::ValidBatch;

/// A sampled batch: the items, and beside them what the learner needs to
/// weight the loss and update priorities. Entry `i` of `keys` and
/// `weights` belongs to transition `i` of `batch`; the priorities the items
/// had when sampled are the batch's `priorities` column.
///
/// `B` is the batch: a [`ValidBatch`] once it entered a process (what a
/// client receives); a plain [`TransitionBatch`](crate::TransitionBatch) as
/// a replay table makes it, from items it validated when they were
/// inserted.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample<B = ValidBatch> {
    /// Item keys, in batch order; they name the items in a priority
    /// update.
    pub keys: Vec<u64>,
    /// Importance weights, in batch order, at most 1.
    pub weights: Vec<f32>,
    /// The transitions, each observation once.
    pub batch: B,
}

/// What a priority update did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PrioritiesUpdated {
    /// Keys whose priority was set.
    pub updated: u32,
    /// Keys of items evicted since they were sampled; ignored.
    pub ignored: u32,
}
