//! Batches from actors on this host over iceoryx2 shared memory, into the
//! same tables the gRPC service fills.
//!
//! One thread (iceoryx2 ports stay on the thread that made them) holds a
//! subscriber per table on `<prefix>/replay/<table>/insert`. Each sample is
//! read in place from shared memory, validated like a gRPC batch and
//! released before the insert, which waits for the rate limiter without
//! dropping the batch. Publishers are served in turn: iceoryx2 hands out
//! the first publisher's samples while it has any, so under a rate limiter
//! one busy actor would starve the others (seen with two actors: the second
//! waited 30 s for acknowledgements and fell back to dropping). The thread
//! queues every waiting sample per publisher and inserts one batch of each
//! in turn; the publishers' limit on unacknowledged batches
//! (`actor.in_flight`) bounds those queues and is where they feel the
//! back-pressure. Batches take gRPC's insert path ([`crate::insert`]); the
//! thread goes on with the next while the write-ahead log syncs. Every
//! batch is answered on `<prefix>/replay/<table>/acks` once stored or
//! rejected. At shutdown the queue is drained into the tables, whatever the
//! rate limiter says, before the server's last snapshot.

use std::collections::VecDeque;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use crossroads_config::TransportConfig;
use crossroads_transport::shm::{self, ShmError};
use crossroads_types::batch::{BatchError, RejectReason, ValidBatch};

use crate::insert::{Admission, InFlight, InsertError};
use crate::metrics::Transport;
use crate::service::State;
use crate::table::{PreparedBatch, Table, TableError};

/// How long the thread sleeps when every queue is empty.
const IDLE: Duration = Duration::from_millis(1);

/// The running ingest thread. [`ShmIngest::join`] waits for it after
/// shutdown fired.
#[derive(Debug)]
pub(crate) struct ShmIngest {
    thread: JoinHandle<()>,
}

impl ShmIngest {
    /// Starts the thread and returns once every subscriber is ready (or
    /// with the error that prevented it). Must be called inside a tokio
    /// runtime, whose handle the thread uses to wait for the rate limiter.
    pub(crate) fn start(config: &TransportConfig, state: Arc<State>) -> Result<Self, ShmError> {
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let config = config.clone();
        let runtime = tokio::runtime::Handle::current();
        let services: Vec<String> = state
            .tables
            .keys()
            .map(|t| shm::service_name(&config.shm_prefix, t))
            .collect();
        let thread = std::thread::Builder::new()
            .name("replay-shm-ingest".to_owned())
            .spawn(move || {
                let setup = || -> Result<_, ShmError> {
                    let node = shm::node()?;
                    let mut subscribers = Vec::new();
                    for (name, table) in &state.tables {
                        let service = shm::open_batch_service(&node, &config, name)?;
                        let subscriber = service
                            .subscriber_builder()
                            .buffer_size(config.shm_buffer)
                            .create()
                            .map_err(|e| ShmError::iceoryx("creating subscriber", e))?;
                        let ack_service = shm::open_ack_service(&node, &config, name)?;
                        let acks = ack_service
                            .publisher_builder()
                            .create()
                            .map_err(|e| ShmError::iceoryx("creating ack publisher", e))?;
                        subscribers.push(Port {
                            table: table.clone(),
                            subscriber,
                            acks,
                            _service: service,
                            _ack_service: ack_service,
                        });
                    }
                    Ok((node, subscribers))
                };
                let (_node, subscribers) = match setup() {
                    Ok(ok) => {
                        let _ = ready_tx.send(Ok(()));
                        ok
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                let send = |port: &Port, origin: u128, batch_id: u64, outcome| {
                    let ack = shm::ShmInsertAck::new(origin, batch_id, outcome);
                    if let Err(e) = port.acks.send_copy(ack) {
                        tracing::warn!(error = ?e, "sending a shared-memory acknowledgement");
                    }
                };
                // Acknowledgements waiting for the write-ahead log, oldest
                // first: the thread goes on inserting meanwhile, so one
                // fsync covers many batches (as for gRPC).
                let acknowledge = |port: &Port, waiting: &mut VecDeque<Waiting>, block: bool| {
                    while let Some(w) = waiting.pop_front() {
                        let (origin, batch_id) = (w.origin, w.batch_id);
                        let outcome = match w.flight.try_finish(block) {
                            Ok(outcome) => outcome,
                            Err(flight) => {
                                waiting.push_front(Waiting {
                                    origin,
                                    batch_id,
                                    flight,
                                });
                                break;
                            }
                        };
                        let outcome = outcome
                            .map(|done| (done.inserted, done.size))
                            .map_err(|e| refused(&state, &port.table, batch_id, e));
                        send(port, origin, batch_id, outcome);
                    }
                };
                let serve =
                    |port: &Port, queue: &mut FairQueue, waiting: &mut VecDeque<Waiting>| -> bool {
                        acknowledge(port, waiting, false);
                        queue.take_all(&port.subscriber);
                        let Some(r) = queue.next() else {
                            return false;
                        };
                        match handle(&state, &runtime, &port.table, r.read) {
                            Ok(flight) => {
                                waiting.push_back(Waiting {
                                    origin: r.origin,
                                    batch_id: r.batch_id,
                                    flight,
                                });
                                // Stored already with the log off: answered now.
                                acknowledge(port, waiting, false);
                            }
                            Err(reason) => send(port, r.origin, r.batch_id, Err(reason)),
                        }
                        true
                    };
                let mut queues: Vec<(FairQueue, VecDeque<Waiting>)> = subscribers
                    .iter()
                    .map(|_| (FairQueue::default(), VecDeque::new()))
                    .collect();
                while !state.shutdown.is_triggered() {
                    let mut busy = false;
                    for (port, (queue, waiting)) in subscribers.iter().zip(&mut queues) {
                        busy |= serve(port, queue, waiting);
                    }
                    if !busy {
                        std::thread::sleep(IDLE);
                    }
                }
                for (port, (queue, waiting)) in subscribers.iter().zip(&mut queues) {
                    while serve(port, queue, waiting) {}
                    acknowledge(port, waiting, true);
                }
            })
            .map_err(|e| ShmError::iceoryx("starting the ingest thread", e))?;
        match ready_rx.recv() {
            Ok(Ok(())) => {
                tracing::info!(services = ?services, "taking batches over shared memory");
                Ok(Self { thread })
            }
            Ok(Err(e)) => {
                let _ = thread.join();
                Err(e)
            }
            Err(_) => Err(ShmError::Iceoryx {
                what: "starting the ingest thread",
                message: "the thread ended before it was ready".to_owned(),
            }),
        }
    }

    /// Waits for the thread to drain its queues and end (after shutdown
    /// fired). Blocking.
    pub(crate) fn join(self) {
        if self.thread.join().is_err() {
            tracing::error!("the shared-memory ingest thread panicked");
        }
    }
}

type Ipc = iceoryx2::service::ipc::Service;

/// Samples taken per pass at most (a bound on memory; publishers hold
/// back far sooner, at `actor.in_flight` unacknowledged batches each).
const TAKE_MAX: usize = 1024;

/// One received batch, read out of shared memory.
struct Received {
    origin: u128,
    batch_id: u64,
    read: Result<(String, u64, ValidBatch), BatchError>,
}

/// Received batches by publisher, served one publisher after another.
#[derive(Default)]
struct FairQueue {
    by_origin: std::collections::BTreeMap<u128, VecDeque<Received>>,
    last: Option<u128>,
}

impl FairQueue {
    /// Takes every sample waiting on `subscriber` (at most [`TAKE_MAX`]),
    /// releasing the shared memory at once.
    fn take_all(
        &mut self,
        subscriber: &iceoryx2::port::subscriber::Subscriber<Ipc, [u8], shm::BatchFrameHeader>,
    ) {
        for _ in 0..TAKE_MAX {
            match subscriber.receive() {
                Ok(Some(sample)) => {
                    let r = Received {
                        origin: sample.origin().value(),
                        batch_id: sample.user_header().batch_id,
                        read: shm::read_frame(sample.user_header(), sample.payload()),
                    };
                    self.push(r);
                }
                Ok(None) => break,
                Err(e) => {
                    tracing::warn!(error = ?e, "receiving from shared memory");
                    break;
                }
            }
        }
    }

    fn push(&mut self, r: Received) {
        self.by_origin.entry(r.origin).or_default().push_back(r);
    }

    /// The oldest batch of the publisher after the last one served.
    fn next(&mut self) -> Option<Received> {
        let after = self
            .last
            .and_then(|l| {
                use std::ops::Bound::{Excluded, Unbounded};
                self.by_origin.range((Excluded(l), Unbounded)).next()
            })
            .map(|(k, _)| *k);
        let origin = after.or_else(|| self.by_origin.keys().next().copied())?;
        let queue = self.by_origin.get_mut(&origin)?;
        let r = queue.pop_front();
        if queue.is_empty() {
            self.by_origin.remove(&origin);
        }
        self.last = Some(origin);
        r
    }
}

/// An admitted batch whose acknowledgement waits for the write-ahead log.
struct Waiting {
    origin: u128,
    batch_id: u64,
    flight: InFlight,
}

/// One table's shared-memory ports.
struct Port {
    table: Arc<Table>,
    subscriber: iceoryx2::port::subscriber::Subscriber<Ipc, [u8], shm::BatchFrameHeader>,
    acks: iceoryx2::port::publisher::Publisher<Ipc, shm::ShmInsertAck, ()>,
    _service: iceoryx2::service::port_factory::publish_subscribe::PortFactory<
        Ipc,
        [u8],
        shm::BatchFrameHeader,
    >,
    _ack_service:
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, shm::ShmInsertAck, ()>,
}

/// Checks the table and size of one received (validated) batch, prepares
/// it and begins its insert, waiting for the rate limiter as long as it
/// takes (at once while draining at shutdown); counts and logs
/// rejections. Returns the insert to acknowledge once finished, or the
/// rejection's reason.
fn handle(
    state: &State,
    runtime: &tokio::runtime::Handle,
    table: &Arc<Table>,
    read: Result<(String, u64, ValidBatch), BatchError>,
) -> Result<InFlight, RejectReason> {
    let (name, batch_id, batch) = read.map_err(|e| rejected(state, table, &e))?;
    if name != table.name() {
        return Err(rejected(
            state,
            table,
            &BatchError::new(
                RejectReason::UnknownTable,
                "table",
                format!("{name:?} sent on the service of table {:?}", table.name()),
            ),
        ));
    }
    state
        .limits
        .check_batch("actions", batch.len())
        .map_err(|e| rejected(state, table, &e))?;
    let prepared = PreparedBatch::new(batch);
    runtime
        .block_on(state.begin_insert(table, prepared, Transport::Shm, Admission::Patient))
        .map_err(|e| refused(state, table, batch_id, e))
}

/// Counts and logs an invalid shared-memory batch; its reason answers it.
fn rejected(state: &State, table: &Table, e: &BatchError) -> RejectReason {
    state.metrics.reject(e.reason);
    tracing::warn!(table = table.name(), reason = %e.reason, error = %e, "rejected a shared-memory batch");
    e.reason
}

/// Counts and logs a shared-memory insert that stored nothing; the reason
/// answers it.
fn refused(state: &State, table: &Table, batch_id: u64, e: InsertError) -> RejectReason {
    match e {
        InsertError::LogDown(e) => {
            state.metrics.reject(RejectReason::Unavailable);
            tracing::warn!(table = table.name(), batch_id, error = %e, "refused a shared-memory batch");
            RejectReason::Unavailable
        }
        InsertError::NotDurable(e) => {
            state.metrics.reject(RejectReason::Unavailable);
            tracing::error!(table = table.name(), batch_id, error = %e,
                "a shared-memory batch's write-ahead-log record failed; nothing stored, not acknowledged");
            RejectReason::Unavailable
        }
        InsertError::Table(TableError::Invalid(e)) => rejected(state, table, &e),
        InsertError::Table(e) => {
            tracing::error!(table = table.name(), batch_id, error = %e, "inserting a shared-memory batch");
            RejectReason::BadRequest
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn received(origin: u128, batch_id: u64) -> Received {
        Received {
            origin,
            batch_id,
            read: Err(BatchError::new(
                RejectReason::BadRequest,
                "test",
                String::new(),
            )),
        }
    }

    #[test]
    fn publishers_are_served_in_turn_each_in_order() {
        let mut q = FairQueue::default();
        // A busy publisher (7) queued three batches before the others.
        for (origin, id) in [(7, 0), (7, 1), (7, 2), (3, 0), (u128::MAX, 0), (3, 1)] {
            q.push(received(origin, id));
        }
        let order: Vec<(u128, u64)> = std::iter::from_fn(|| q.next())
            .map(|r| (r.origin, r.batch_id))
            .collect();
        assert_eq!(
            order,
            [(3, 0), (7, 0), (u128::MAX, 0), (3, 1), (7, 1), (7, 2)]
        );
        assert!(q.next().is_none());
    }
}
