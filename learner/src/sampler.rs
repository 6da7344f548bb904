//! The learner's two conversations with the replay server, each a
//! background task: [`spawn_prefetch`] keeps sampled batches decoded and
//! ready while the previous update runs, [`spawn_priority_sender`] sends
//! priority updates without making the training loop wait.
//!
//! Both are gRPC (the learner has no iceoryx2 path to the replay). Each
//! sample request carries the importance exponent beta of [`BetaSchedule`],
//! read from the training thread's update count; what a retry can fix
//! (server down, rate limited) is retried with backoff, what it cannot ends
//! the prefetcher with an error. A priority update that finds the sender's
//! queue full is counted as dropped, not waited for.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use crossroads_common::{Backoff, Shutdown};
use crossroads_config::LearnerConfig;
use crossroads_model::NetworkSpec;
use crossroads_transport::grpc::ReplayClient;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::LearnerError;
use crate::batch::TrainingBatch;
use crate::metrics::LearnerMetrics;

/// What the prefetcher hands over: a batch ready for an update, or the
/// error that stopped it.
pub type Prefetched = Result<TrainingBatch, LearnerError>;

/// Longest a sample request waits for the replay's rate limiter before it
/// is asked again (so shutdown and logs stay timely).
const SAMPLE_WAIT: Duration = Duration::from_secs(1);

/// The importance-sampling exponent over a run: linear from `start` to
/// `end` over `updates` updates, then `end` (Schaul et al.'s anneal to 1:
/// with stochastic outcomes, a beta below 1 leaves Q biased towards the
/// outcomes prioritized replay oversamples).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BetaSchedule {
    /// Beta at update 0.
    pub start: f64,
    /// Beta from `updates` on.
    pub end: f64,
    /// Length of the anneal; 0 keeps `start`.
    pub updates: u64,
}

impl BetaSchedule {
    /// `[learner]`'s schedule: `importance_beta` to `importance_beta_final`
    /// over `importance_beta_updates`, or over `max_updates` when that is 0.
    pub fn from_config(c: &LearnerConfig) -> Self {
        let updates = match c.importance_beta_updates {
            0 => c.max_updates,
            n => n,
        };
        Self {
            start: c.importance_beta,
            end: c.importance_beta_final,
            updates,
        }
    }

    /// Beta after `step` updates.
    pub fn at(&self, step: u64) -> f32 {
        if self.updates == 0 {
            return self.start as f32;
        }
        let f = (step as f64 / self.updates as f64).min(1.0);
        (self.start + f * (self.end - self.start)) as f32
    }
}

/// What the prefetcher asks for.
#[derive(Debug, Clone)]
pub struct PrefetchConfig {
    /// Transitions per batch.
    pub batch_size: u32,
    /// Importance exponent over the run.
    pub beta: BetaSchedule,
    /// Updates applied so far (the training thread's count), which picks
    /// beta for each request.
    pub steps: Arc<AtomicU64>,
    /// Batches kept ready.
    pub depth: usize,
    /// The network the batches must fit.
    pub spec: NetworkSpec,
}

/// Samples continuously, keeping up to `depth` decoded batches in the
/// returned channel. Retries what can succeed later (server down, rate
/// limited) with backoff; a batch that does not fit the network or a
/// request the server refuses is sent as an error, and the task ends.
pub fn spawn_prefetch(
    client: ReplayClient,
    config: PrefetchConfig,
    mut backoff: Backoff,
    metrics: LearnerMetrics,
    shutdown: Shutdown,
) -> (mpsc::Receiver<Prefetched>, JoinHandle<()>) {
    let (tx, rx) = mpsc::channel(config.depth.max(1));
    let task = tokio::spawn(async move {
        let mut warned = false;
        loop {
            let sampled = tokio::select! {
                _ = shutdown.wait() => break,
                r = client.sample(config.batch_size, config.beta.at(config.steps.load(Ordering::Relaxed)), SAMPLE_WAIT) => r,
            };
            match sampled {
                Ok(sampled) => {
                    if warned {
                        tracing::info!("sampling from the replay server again");
                        warned = false;
                    }
                    backoff.reset();
                    let batch = TrainingBatch::from_sampled(&sampled, &config.spec);
                    let fatal = batch.is_err();
                    let sent = tokio::select! {
                        _ = shutdown.wait() => break,
                        r = tx.send(batch) => r,
                    };
                    if sent.is_err() || fatal {
                        break;
                    }
                }
                Err(e) if e.code() == Some(tonic::Code::DeadlineExceeded) => {
                    // The rate limiter holds sampling back (the table is
                    // filling); the server already waited, so ask again.
                    if !warned {
                        tracing::info!(error = %e, "waiting for the replay server to allow sampling");
                        warned = true;
                    }
                }
                Err(e) if e.is_retryable() => {
                    metrics.replay_errors.with_label_values(&["sample"]).inc();
                    let delay = backoff.next_delay();
                    if !warned {
                        tracing::warn!(error = %e, retry_in = ?delay, "sampling from the replay server failed; retrying");
                        warned = true;
                    }
                    tokio::select! {
                        _ = shutdown.wait() => break,
                        _ = tokio::time::sleep(delay) => {}
                    }
                }
                Err(e) => {
                    metrics.replay_errors.with_label_values(&["sample"]).inc();
                    let _ = tx.send(Err(e.into())).await;
                    break;
                }
            }
        }
    });
    (rx, task)
}

/// New priorities for sampled items, from one update: what the learner
/// sends (the replay's answer is `crossroads_transport::PriorityUpdate`).
#[derive(Debug, Clone, PartialEq)]
pub struct NewPriorities {
    /// Item keys, in batch order.
    pub keys: Vec<u64>,
    /// Their new priorities, in the same order.
    pub priorities: Vec<f32>,
}

/// Sends priority updates in order, in the background. The training loop
/// `try_send`s into the returned channel (of `capacity` updates) and counts
/// an update as dropped when it is full rather than wait. Failures are
/// counted and logged; a lost update only leaves old priorities in place.
pub fn spawn_priority_sender(
    client: ReplayClient,
    capacity: usize,
    metrics: LearnerMetrics,
    shutdown: Shutdown,
) -> (mpsc::Sender<NewPriorities>, JoinHandle<()>) {
    let (tx, mut rx) = mpsc::channel::<NewPriorities>(capacity.max(1));
    let task = tokio::spawn(async move {
        let mut failing = false;
        loop {
            let update = tokio::select! {
                _ = shutdown.wait() => break,
                u = rx.recv() => u,
            };
            let Some(NewPriorities { keys, priorities }) = update else {
                break;
            };
            match client.update_priorities(keys, priorities).await {
                Ok(_) => {
                    if failing {
                        tracing::info!("priority updates reach the replay server again");
                        failing = false;
                    }
                }
                Err(e) => {
                    metrics
                        .replay_errors
                        .with_label_values(&["update_priorities"])
                        .inc();
                    if !failing {
                        tracing::warn!(error = %e, "priority update failed");
                        failing = true;
                    }
                }
            }
        }
    });
    (tx, task)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beta_anneals_linearly_then_holds() {
        let mut c = LearnerConfig {
            max_updates: 1000,
            ..LearnerConfig::default()
        };
        let s = BetaSchedule::from_config(&c);
        assert_eq!((s.start, s.end, s.updates), (0.4, 1.0, 1000));
        assert!((s.at(0) - 0.4).abs() < 1e-6);
        assert!((s.at(500) - 0.7).abs() < 1e-6);
        assert!((s.at(1000) - 1.0).abs() < 1e-6);
        assert!((s.at(5000) - 1.0).abs() < 1e-6);
        // Its own span wins over max_updates; with neither, beta stays.
        c.importance_beta_updates = 100;
        assert!((BetaSchedule::from_config(&c).at(50) - 0.7).abs() < 1e-6);
        c.importance_beta_updates = 0;
        c.max_updates = 0;
        assert!((BetaSchedule::from_config(&c).at(10_000) - 0.4).abs() < 1e-6);
    }
}
