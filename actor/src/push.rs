//! Delivery of batches to the replay server, over gRPC or iceoryx2, with a
//! bounded buffer, backoff and reconnection.
//!
//! A [`Pusher`] owns a [`PushBuffer`] and one background worker: a tokio
//! task for gRPC (a streaming insert with up to `in_flight` batches
//! unacknowledged), a dedicated thread for iceoryx2 (the publisher is not
//! `Send`). A failed send or connection puts the unacknowledged batches
//! back at the front of the buffer and waits with exponential backoff and
//! jitter ([`Backoff`]); the next attempt reconnects. Delivery is
//! at-least-once: a batch whose acknowledgement was lost is sent again.
//! Nothing here panics on a network error.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crossroads_common::{Backoff, Shutdown};
use crossroads_config::ActorTransport;
use crossroads_config::TransportConfig;
use crossroads_transport::grpc::{ClientError, InsertStream, ReplayClient};
use crossroads_transport::shm::{ShmBatchPublisher, ShmError};
use crossroads_types::{TransitionBatch, ValidBatch};

use crate::buffer::PushBuffer;
use crate::error::ActorError;
use crate::metrics::ActorMetrics;
use crate::worker::Worker;

/// Where and how a [`Pusher`] delivers.
#[derive(Debug, Clone)]
pub struct PushConfig {
    /// gRPC or iceoryx2.
    pub transport: ActorTransport,
    /// Endpoint, timeouts, backoff and shared-memory settings.
    pub connection: TransportConfig,
    /// The replay table.
    pub table: String,
    /// Batches kept while the replay is unreachable.
    pub buffer_batches: usize,
    /// Batches sent and not acknowledged at once.
    pub in_flight: usize,
}

impl PushConfig {
    /// From the `[actor]`, `[transport]` and `[replay]` sections.
    pub fn from_config(config: &crossroads_config::Config) -> Self {
        Self {
            transport: config.actor.transport,
            connection: config.transport.clone(),
            table: config.replay.table.clone(),
            buffer_batches: config.actor.buffer_batches,
            in_flight: config.actor.in_flight,
        }
    }
}

/// Delivers batches in the background; see the module docs. Dropping it
/// without [`close`](Self::close) stops the worker at its next check and
/// loses what is buffered.
#[derive(Debug)]
pub struct Pusher {
    buffer: Arc<PushBuffer>,
    closing: Arc<AtomicBool>,
    healthy: Arc<AtomicBool>,
    high_water: usize,
    stop: Shutdown,
    worker: Option<Worker>,
}

impl Pusher {
    /// Starts the worker for `config.transport`. gRPC needs a tokio
    /// runtime; the replay server need not be up. `shutdown` stops the
    /// worker at once (without draining).
    pub fn start(
        config: &PushConfig,
        metrics: ActorMetrics,
        shutdown: &Shutdown,
    ) -> Result<Self, ActorError> {
        let buffer = Arc::new(PushBuffer::new(config.buffer_batches, metrics.clone()));
        let closing = Arc::new(AtomicBool::new(false));
        // Optimistic until a call fails, so the first batches wait for a
        // replay that is still connecting rather than being dropped.
        let healthy = Arc::new(AtomicBool::new(true));
        let stop = shutdown.child();
        let ctx = Ctx {
            buffer: Arc::clone(&buffer),
            closing: Arc::clone(&closing),
            healthy: Arc::clone(&healthy),
            stop: stop.clone(),
            metrics,
            connection: config.connection.clone(),
            table: config.table.clone(),
            in_flight: config.in_flight.max(1),
        };
        let worker = match config.transport {
            ActorTransport::Grpc => {
                let client = ReplayClient::new(&config.connection, &config.table)?;
                Worker::Task(tokio::spawn(grpc_worker(ctx, client)))
            }
            ActorTransport::Shm => {
                Worker::thread("actor-shm-push", "push", move || shm_worker(ctx))?
            }
        };
        Ok(Self {
            buffer,
            closing,
            healthy,
            high_water: config.in_flight.max(1),
            stop,
            worker: Some(worker),
        })
    }

    /// Queues a batch; never blocks (drops the oldest when the buffer is
    /// full).
    pub fn push(&self, batch: TransitionBatch) {
        if !batch.is_empty() {
            self.buffer.push(batch);
        }
    }

    /// Whether the replay answers but takes batches more slowly than they
    /// come (its rate limiter holds inserts back): more than `in_flight`
    /// batches wait and the last call succeeded. The acting loop then
    /// waits instead of filling the buffer; an unreachable replay is not
    /// backlogged, so the actor acts on and the buffer drops the oldest.
    pub fn backlogged(&self) -> bool {
        self.healthy.load(Ordering::Relaxed) && self.buffer.len() > self.high_water
    }

    /// Batches waiting to be sent.
    pub fn buffered(&self) -> usize {
        self.buffer.len()
    }

    /// The buffer (for its length and capacity).
    pub fn buffer(&self) -> &Arc<PushBuffer> {
        &self.buffer
    }

    /// Delivers what is buffered, for at most `drain`, then stops the
    /// worker (an iceoryx2 publisher flushes before it goes).
    pub async fn close(mut self, drain: Duration) {
        self.closing.store(true, Ordering::SeqCst);
        self.buffer.wake();
        let stop = self.stop.clone();
        let worker = self.worker.take();
        let waited = async move {
            if let Some(worker) = worker
                && let Err(e) = worker.join().await
            {
                tracing::error!(error = %e, "push worker failed");
            }
        };
        tokio::pin!(waited);
        if tokio::time::timeout(drain, &mut waited).await.is_err() {
            let left = self.buffer.len();
            tracing::warn!(left, "push buffer not drained in {drain:?}; stopping");
            stop.trigger();
            let _ = tokio::time::timeout(Duration::from_secs(10), waited).await;
        }
    }
}

impl Drop for Pusher {
    fn drop(&mut self) {
        if self.worker.is_some() {
            self.stop.trigger();
        }
    }
}

struct Ctx {
    buffer: Arc<PushBuffer>,
    closing: Arc<AtomicBool>,
    /// The last call succeeded (cleared by a failure).
    healthy: Arc<AtomicBool>,
    stop: Shutdown,
    metrics: ActorMetrics,
    connection: TransportConfig,
    table: String,
    in_flight: usize,
}

impl Ctx {
    /// Whether the worker is done: stopped, or closing with nothing left.
    fn finished(&self, in_flight: usize) -> bool {
        self.stop.is_triggered()
            || (self.closing.load(Ordering::SeqCst) && in_flight == 0 && self.buffer.is_empty())
    }
}

struct Sent {
    batch: TransitionBatch,
    at: Instant,
}

async fn grpc_worker(ctx: Ctx, client: ReplayClient) {
    let mut backoff = Backoff::from_config(&ctx.connection);
    let mut stream: Option<InsertStream> = None;
    let mut sent: VecDeque<Sent> = VecDeque::new();
    loop {
        if ctx.finished(sent.len()) {
            break;
        }
        let s = match stream.as_mut() {
            Some(s) => s,
            None => match client.insert_stream(ctx.in_flight).await {
                Ok(s) => stream.insert(s),
                Err(e) => {
                    grpc_failed(&ctx, &e, &mut sent, &mut backoff).await;
                    continue;
                }
            },
        };
        if !s.is_full()
            && let Some(batch) = ctx.buffer.try_pop()
        {
            let at = Instant::now();
            match s.send(batch.clone()).await {
                Ok(_) => sent.push_back(Sent { batch, at }),
                // Refused before it left (too large for one message): the
                // stream is still good.
                Err(e) if !e.is_retryable() => {
                    tracing::warn!(error = %e, transitions = batch.len(), "a batch cannot be sent; dropped");
                    ctx.metrics.dropped("rejected", batch.len() as u64);
                }
                Err(e) => {
                    sent.push_back(Sent { batch, at });
                    stream = None;
                    grpc_failed(&ctx, &e, &mut sent, &mut backoff).await;
                }
            }
            continue;
        }
        if !sent.is_empty() {
            match s.next_ack().await {
                Ok(ack) => {
                    if let Some(done) = sent.pop_front() {
                        ctx.metrics.pushed(
                            "grpc",
                            u64::from(ack.inserted),
                            done.at.elapsed().as_secs_f64(),
                        );
                    }
                    ctx.healthy.store(true, Ordering::Relaxed);
                    backoff.reset();
                }
                Err(e) => {
                    stream = None;
                    grpc_failed(&ctx, &e, &mut sent, &mut backoff).await;
                }
            }
            continue;
        }
        tokio::select! {
            _ = ctx.buffer.wait(Duration::from_millis(100)) => {}
            _ = ctx.stop.wait() => {}
        }
    }
    if let Some(s) = stream
        && let Err(e) = s.finish().await
    {
        tracing::debug!(error = %e, "closing the insert stream");
    }
}

/// After a failed call: when the server refused the oldest batch in flight
/// (a status no retry changes), that one is dropped and counted; the rest
/// go back to the buffer; then a backoff.
async fn grpc_failed(ctx: &Ctx, e: &ClientError, sent: &mut VecDeque<Sent>, backoff: &mut Backoff) {
    ctx.metrics.retry("grpc");
    ctx.healthy.store(false, Ordering::Relaxed);
    if !e.is_retryable()
        && let Some(bad) = sent.pop_front()
    {
        // The stream ends at the first refused batch; the ones after it were
        // not looked at.
        tracing::warn!(error = %e, transitions = bad.batch.len(), "the replay server refused a batch; dropped");
        ctx.metrics.dropped("rejected", bad.batch.len() as u64);
    }
    ctx.buffer.requeue(sent.drain(..).map(|s| s.batch));
    let delay = backoff.next_delay();
    if backoff.attempts() <= 1 || backoff.attempts().is_power_of_two() {
        tracing::warn!(error = %e, attempts = backoff.attempts(), retry_in = ?delay, buffered = ctx.buffer.len(), "replay server unreachable over gRPC; buffering");
    }
    tokio::select! {
        _ = tokio::time::sleep(delay) => {}
        _ = ctx.stop.wait() => {}
    }
}

fn shm_worker(ctx: Ctx) {
    let mut backoff = Backoff::from_config(&ctx.connection);
    let ack_timeout = Duration::from_millis(ctx.connection.request_timeout_ms);
    let mut publisher: Option<ShmBatchPublisher> = None;
    let mut sent: VecDeque<(u64, Sent)> = VecDeque::new();
    let mut next_id = 0u64;
    loop {
        if ctx.finished(sent.len()) {
            break;
        }
        let p = match publisher.as_mut() {
            Some(p) => p,
            None => match ShmBatchPublisher::new(&ctx.connection, &ctx.table) {
                Ok(p) => publisher.insert(p),
                Err(e) => {
                    shm_failed(&ctx, &e, &mut backoff);
                    continue;
                }
            },
        };
        match p.poll_acks() {
            Ok(acks) => {
                for ack in acks {
                    let Some(i) = sent.iter().position(|(id, _)| *id == ack.batch_id) else {
                        continue;
                    };
                    let Some((_, done)) = sent.remove(i) else {
                        continue;
                    };
                    match ack.outcome {
                        Ok((inserted, _)) => {
                            ctx.metrics.pushed(
                                "shm",
                                u64::from(inserted),
                                done.at.elapsed().as_secs_f64(),
                            );
                            ctx.healthy.store(true, Ordering::Relaxed);
                            backoff.reset();
                        }
                        Err(reason) => {
                            tracing::warn!(%reason, transitions = done.batch.len(), "the replay server refused a batch; dropped");
                            ctx.metrics.dropped("rejected", done.batch.len() as u64);
                        }
                    }
                }
            }
            Err(e) => {
                publisher = None;
                shm_failed(&ctx, &e, &mut backoff);
                continue;
            }
        }
        // A server that went away took its queue with it: what it never
        // answered is sent again.
        if sent
            .front()
            .is_some_and(|(_, s)| s.at.elapsed() > ack_timeout)
        {
            tracing::warn!(
                pending = sent.len(),
                "batches unacknowledged after {ack_timeout:?}; sending them again"
            );
            ctx.metrics.retry("shm");
            ctx.healthy.store(false, Ordering::Relaxed);
            ctx.buffer.requeue(sent.drain(..).map(|(_, s)| s.batch));
        }
        if sent.len() >= ctx.in_flight {
            std::thread::sleep(Duration::from_millis(1));
            continue;
        }
        let wait = if sent.is_empty() {
            Duration::from_millis(50)
        } else {
            Duration::from_millis(1)
        };
        let Some(batch) = ctx.buffer.pop_timeout(wait) else {
            continue;
        };
        let id = next_id;
        next_id += 1;
        let transitions = batch.len() as u64;
        let drop_invalid = |e: &dyn std::fmt::Display| {
            tracing::warn!(error = %e, "an invalid batch was not sent; dropped");
            ctx.metrics.dropped("rejected", transitions);
        };
        // Checked once, here: shared memory carries only valid batches.
        let batch = match ValidBatch::new(batch) {
            Ok(batch) => batch,
            Err(e) => {
                drop_invalid(&e);
                continue;
            }
        };
        match p.send(id, &batch) {
            Ok(()) => sent.push_back((
                id,
                Sent {
                    batch: batch.into_inner(),
                    at: Instant::now(),
                },
            )),
            Err(ShmError::Invalid(e)) => drop_invalid(&e),
            Err(e) => {
                ctx.buffer.requeue(std::iter::once(batch.into_inner()));
                if matches!(e, ShmError::Iceoryx { .. }) {
                    publisher = None;
                }
                shm_failed(&ctx, &e, &mut backoff);
            }
        }
    }
    // iceoryx2 drops what a vanished publisher left queued: wait for the
    // answers first.
    if let Some(mut p) = publisher
        && !sent.is_empty()
    {
        let drain = if ctx.stop.is_triggered() {
            Duration::from_millis(100)
        } else {
            ack_timeout
        };
        match p.flush(drain) {
            Ok(acks) => {
                for ack in acks {
                    if let Ok((inserted, _)) = ack.outcome {
                        ctx.metrics.pushed("shm", u64::from(inserted), 0.0);
                    }
                }
            }
            Err(e) => tracing::warn!(error = %e, "flushing the shared-memory publisher"),
        }
    }
}

fn shm_failed(ctx: &Ctx, e: &ShmError, backoff: &mut Backoff) {
    ctx.metrics.retry("shm");
    ctx.healthy.store(false, Ordering::Relaxed);
    let delay = backoff.next_delay();
    if backoff.attempts() <= 1 || backoff.attempts().is_power_of_two() {
        tracing::warn!(error = %e, attempts = backoff.attempts(), retry_in = ?delay, buffered = ctx.buffer.len(), "replay server unreachable over shared memory; buffering");
    }
    // Sleep in slices, so a shutdown is seen quickly.
    let until = Instant::now() + delay;
    while Instant::now() < until && !ctx.stop.is_triggered() {
        std::thread::sleep((until - Instant::now()).min(Duration::from_millis(20)));
    }
}
