//! Batches from actors on this host over iceoryx2 shared memory, into the
//! same tables the gRPC service fills.
//!
//! One thread (iceoryx2 ports stay on the thread that made them) holds a
//! subscriber per table on `<prefix>/replay/<table>/insert`. Each sample is
//! read in place from shared memory, validated like a gRPC batch and
//! released before the insert, which waits for the rate limiter without
//! dropping the batch: while it waits the queue fills and publishers feel
//! the back-pressure (their sends time out), rather than batches being lost
//! here. Every batch is answered on `<prefix>/replay/<table>/acks` once
//! stored or rejected. At shutdown the queue is drained into the tables,
//! whatever the rate limiter says, before the server's last snapshot.

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use crossroads_common::batch::{BatchError, RejectReason};
use crossroads_common::config::TransportConfig;
use crossroads_common::transport::shm::{self, ShmError};

use crate::metrics::Transport;
use crate::service::State;
use crate::table::{PreparedBatch, Table, TableError};

/// How long the thread sleeps when every queue is empty.
const IDLE: Duration = Duration::from_millis(1);

/// The running ingest thread. [`ShmIngest::join`] waits for it after
/// shutdown fired.
#[derive(Debug)]
pub struct ShmIngest {
    thread: JoinHandle<()>,
    services: Vec<String>,
}

impl ShmIngest {
    /// Starts the thread and returns once every subscriber is ready (or
    /// with the error that prevented it). Must be called inside a tokio
    /// runtime, whose handle the thread uses to wait for the rate limiter.
    pub fn start(config: &TransportConfig, state: Arc<State>) -> Result<Self, ShmError> {
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
                let receive = |port: &Port, draining: bool| -> bool {
                    match port.subscriber.receive() {
                        Ok(Some(sample)) => {
                            let read = shm::read_frame(sample.user_header(), sample.payload());
                            let origin = sample.origin().value();
                            let batch_id = sample.user_header().batch_id;
                            // The shared-memory slot goes back to the
                            // publisher before the insert may wait.
                            drop(sample);
                            let outcome = handle(&state, &runtime, &port.table, read, draining);
                            let ack = shm::ShmInsertAck::new(origin, batch_id, outcome);
                            if let Err(e) = port.acks.send_copy(ack) {
                                tracing::warn!(error = ?e, "sending a shared-memory acknowledgement");
                            }
                            true
                        }
                        Ok(None) => false,
                        Err(e) => {
                            tracing::warn!(error = ?e, "receiving from shared memory");
                            false
                        }
                    }
                };
                while !state.shutdown.is_triggered() {
                    let mut busy = false;
                    for port in &subscribers {
                        busy |= receive(port, false);
                    }
                    if !busy {
                        std::thread::sleep(IDLE);
                    }
                }
                for port in &subscribers {
                    while receive(port, true) {}
                }
            })
            .map_err(|e| ShmError::iceoryx("starting the ingest thread", e))?;
        match ready_rx.recv() {
            Ok(Ok(())) => {
                tracing::info!(services = ?services, "taking batches over shared memory");
                Ok(Self { thread, services })
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

    /// The iceoryx2 services subscribed to.
    pub fn services(&self) -> &[String] {
        &self.services
    }

    /// Waits for the thread to drain its queues and end (after shutdown
    /// fired). Blocking.
    pub fn join(self) {
        if self.thread.join().is_err() {
            tracing::error!("the shared-memory ingest thread panicked");
        }
    }
}

type Ipc = iceoryx2::service::ipc::Service;

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

/// Validates, prepares and inserts one received batch; counts and logs
/// rejections. Returns what to acknowledge: `(inserted, table size)` or
/// the rejection's reason.
fn handle(
    state: &State,
    runtime: &tokio::runtime::Handle,
    table: &Arc<Table>,
    read: Result<(String, u64, crossroads_common::TransitionBatch), BatchError>,
    draining: bool,
) -> Result<(u32, u64), RejectReason> {
    let reject = |e: BatchError| {
        state.metrics.reject(e.reason);
        tracing::warn!(table = table.name(), reason = %e.reason, error = %e, "rejected a shared-memory batch");
        Err(e.reason)
    };
    let (name, batch_id, batch) = match read {
        Ok(ok) => ok,
        Err(e) => return reject(e),
    };
    if name != table.name() {
        return reject(BatchError::new(
            RejectReason::UnknownTable,
            "table",
            format!("{name:?} sent on the service of table {:?}", table.name()),
        ));
    }
    if batch.len() > state.limits.max_batch_transitions {
        return reject(BatchError::new(
            RejectReason::Oversized,
            "actions",
            format!(
                "{} transitions, above {}",
                batch.len(),
                state.limits.max_batch_transitions
            ),
        ));
    }
    let prepared = match PreparedBatch::new(batch) {
        Ok(p) => p,
        Err(e) => return reject(e),
    };
    let mut now = draining;
    loop {
        let outcome = if now {
            table.insert_now(&prepared)
        } else {
            runtime.block_on(table.insert(&prepared, state.limits.insert_timeout, &state.shutdown))
        };
        match outcome {
            Ok(done) => {
                table
                    .metrics()
                    .inserted(Transport::Shm, u64::from(done.inserted));
                return Ok((done.inserted, done.size));
            }
            // Keep the batch and keep waiting: the full queue pushes back on
            // the publishers meanwhile.
            Err(TableError::Timeout { .. }) => continue,
            // Received, so stored: the last snapshot comes after this.
            Err(TableError::ShuttingDown) => now = true,
            Err(TableError::Invalid(e)) => return reject(e),
            Err(e) => {
                tracing::error!(table = table.name(), batch_id, error = %e, "inserting a shared-memory batch");
                return Err(RejectReason::BadRequest);
            }
        }
    }
}
