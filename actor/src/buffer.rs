//! The bounded buffer between the acting loop and the pusher.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::Duration;

use crossroads_types::TransitionBatch;

use crate::metrics::ActorMetrics;

/// Batches waiting to be sent, at most `capacity`; when full, the oldest is
/// dropped (and its transitions counted as `buffer_full`), so an actor
/// keeps acting while the replay is unreachable and sends its freshest
/// experience when it is back. [`push`](Self::push) never blocks.
/// Thread-safe; the acting loop pushes, one pusher (a task or a thread)
/// pops, either synchronously or asynchronously.
#[derive(Debug)]
pub struct PushBuffer {
    queue: Mutex<VecDeque<TransitionBatch>>,
    capacity: usize,
    ready: Condvar,
    notify: tokio::sync::Notify,
    metrics: ActorMetrics,
}

impl PushBuffer {
    /// A buffer of at most `capacity` (at least 1) batches.
    pub fn new(capacity: usize, metrics: ActorMetrics) -> Self {
        Self {
            queue: Mutex::new(VecDeque::new()),
            capacity: capacity.max(1),
            ready: Condvar::new(),
            notify: tokio::sync::Notify::new(),
            metrics,
        }
    }

    fn lock(&self) -> MutexGuard<'_, VecDeque<TransitionBatch>> {
        // A panic while holding the lock cannot leave the queue torn (every
        // operation is one VecDeque call), so a poisoned lock is usable.
        self.queue
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Appends a batch, dropping the oldest when full.
    pub fn push(&self, batch: TransitionBatch) {
        let mut q = self.lock();
        q.push_back(batch);
        self.trim(&mut q);
        self.metrics.buffer_batches.set(q.len() as i64);
        drop(q);
        self.ready.notify_one();
        self.notify.notify_one();
    }

    /// Puts batches that could not be delivered back at the front, oldest
    /// first, dropping the oldest beyond the capacity.
    pub fn requeue(&self, batches: impl DoubleEndedIterator<Item = TransitionBatch>) {
        let mut q = self.lock();
        for b in batches.rev() {
            q.push_front(b);
        }
        self.trim(&mut q);
        self.metrics.buffer_batches.set(q.len() as i64);
    }

    fn trim(&self, q: &mut VecDeque<TransitionBatch>) {
        while q.len() > self.capacity {
            if let Some(old) = q.pop_front() {
                self.metrics.dropped("buffer_full", old.len() as u64);
            }
        }
    }

    /// The oldest batch, if any; does not wait.
    pub fn try_pop(&self) -> Option<TransitionBatch> {
        let mut q = self.lock();
        let b = q.pop_front();
        self.metrics.buffer_batches.set(q.len() as i64);
        b
    }

    /// The oldest batch, waiting at most `timeout` for one.
    pub fn pop_timeout(&self, timeout: Duration) -> Option<TransitionBatch> {
        let q = self.lock();
        let (mut q, _) = self
            .ready
            .wait_timeout_while(q, timeout, |q| q.is_empty())
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let b = q.pop_front();
        self.metrics.buffer_batches.set(q.len() as i64);
        b
    }

    /// Waits until a batch may be there (a push since the last wait), at
    /// most `timeout`.
    pub async fn wait(&self, timeout: Duration) {
        if !self.is_empty() {
            return;
        }
        let _ = tokio::time::timeout(timeout, self.notify.notified()).await;
    }

    /// Wakes a waiting pusher (to see that it should close).
    pub fn wake(&self) {
        self.ready.notify_all();
        self.notify.notify_one();
    }

    /// Batches waiting.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    /// Whether none are.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The capacity, in batches.
    pub fn capacity(&self) -> usize {
        self.capacity
    }
}
