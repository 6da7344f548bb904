//! The gRPC `crossroads.v1.Replay` service over the server's tables;
//! crate-private, so no prost type is in the crate's public API.
//!
//! Each call converts its request into domain types at the boundary
//! ([`crossroads_transport::wire`]), rejecting anything invalid with
//! INVALID_ARGUMENT (RESOURCE_EXHAUSTED when oversized) and a message that
//! names the field, before any table is touched; every rejection is counted
//! by reason. Rate-limiter timeouts are DEADLINE_EXCEEDED, a server
//! shutting down UNAVAILABLE.

use std::collections::BTreeMap;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use crossroads_common::Shutdown;

use crossroads_proto::v1 as pb;
use crossroads_transport::wire;
use crossroads_types::batch::{BatchError, RejectReason};
use tokio::sync::mpsc;
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tokio_util::task::TaskTracker;
use tonic::{Request, Response, Status, Streaming};

use crate::insert::{Admission, InsertError};
use crate::metrics::{ReplayMetrics, Transport};
use crate::roster::Roster;
use crate::snapshot::Snapshots;
use crate::table::{PreparedBatch, Table, TableError};
use crate::wal::{Wal, WalError};

/// Longest wait a sample request may ask for.
const MAX_SAMPLE_WAIT: Duration = Duration::from_secs(600);

/// Per-call limits, from `[replay]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Limits {
    /// Longest an insert waits for the rate limiter.
    pub(crate) insert_timeout: Duration,
    /// Default longest wait of a sample.
    pub(crate) sample_timeout: Duration,
    /// Largest batch, transitions.
    pub(crate) max_batch_transitions: usize,
    /// Largest sample or priority update, items.
    pub(crate) max_sample_batch: usize,
}

impl Limits {
    /// A batch of `n` transitions, refused (`Oversized`, naming `field`)
    /// above `max_batch_transitions`.
    pub(crate) fn check_batch(&self, field: &str, n: usize) -> Result<(), BatchError> {
        let max = self.max_batch_transitions;
        at_most(field, n, max, || {
            format!("{n} transitions, above the server's {max} per batch")
        })
    }

    /// A sample of `n` items, refused above `max_sample_batch`.
    fn check_sample(&self, n: usize) -> Result<(), BatchError> {
        let max = self.max_sample_batch;
        at_most("batch_size", n, max, || {
            format!("{n} is above the server's {max}")
        })
    }

    /// A priority update of `n` keys, refused above `max_sample_batch`.
    fn check_update(&self, n: usize) -> Result<(), BatchError> {
        let max = self.max_sample_batch;
        at_most("keys", n, max, || {
            format!("{n} keys, above the server's {max}")
        })
    }
}

/// `Ok` when `n` is at most `max`; otherwise an `Oversized` rejection of
/// `field` saying `problem()`.
fn at_most(
    field: &str,
    n: usize,
    max: usize,
    problem: impl FnOnce() -> String,
) -> Result<(), BatchError> {
    if n <= max {
        Ok(())
    } else {
        Err(BatchError::new(RejectReason::Oversized, field, problem()))
    }
}

/// What the service and the shared-memory ingest share.
#[derive(Debug)]
pub(crate) struct State {
    /// Tables by name.
    pub(crate) tables: BTreeMap<String, Arc<Table>>,
    /// The process's replay metrics.
    pub(crate) metrics: ReplayMetrics,
    /// Snapshot writer, when a directory is configured.
    pub(crate) snapshots: Option<Arc<Snapshots>>,
    /// The write-ahead log, when on: inserts are acknowledged once in it.
    pub(crate) wal: Option<Arc<Wal>>,
    /// Per-call limits.
    pub(crate) limits: Limits,
    /// Fires when the server stops.
    pub(crate) shutdown: Shutdown,
    /// Tasks serving insert streams; the server waits for them before its
    /// last snapshot, so nothing acknowledged is left out of it.
    pub(crate) tasks: TaskTracker,
    /// Actors that asked for an index.
    pub(crate) roster: Roster,
}

impl State {
    /// The table named `name`, or a counted rejection.
    pub(crate) fn table(&self, name: &str) -> Result<&Arc<Table>, BatchError> {
        self.tables.get(name).ok_or_else(|| {
            BatchError::new(
                RejectReason::UnknownTable,
                "table",
                format!(
                    "no table {name:?}; this server has {:?}",
                    self.tables.keys().collect::<Vec<_>>()
                ),
            )
        })
    }

    /// The table named `name`, or the counted rejection as a status.
    fn table_or_status(&self, name: &str) -> Result<&Arc<Table>, Status> {
        self.accept(self.table(name))
    }

    /// `checked`'s value, or its error counted and turned into a status.
    fn accept<T>(&self, checked: Result<T, BatchError>) -> Result<T, Status> {
        checked.map_err(|e| self.reject(&e))
    }

    /// Counts a rejection and turns it into a status.
    pub(crate) fn reject(&self, e: &BatchError) -> Status {
        self.metrics.reject(e.reason);
        tracing::debug!(reason = %e.reason, error = %e, "rejected input");
        match e.reason {
            RejectReason::Oversized => Status::resource_exhausted(e.to_string()),
            _ => Status::invalid_argument(e.to_string()),
        }
    }

    /// Refuses an insert, before the table changes, while the write-ahead
    /// log cannot write.
    pub(crate) fn check_durable(&self) -> Result<(), WalError> {
        self.wal.as_ref().map_or(Ok(()), |w| w.check_writable())
    }

    fn status(&self, e: TableError) -> Status {
        match e {
            TableError::Invalid(e) => self.reject(&e),
            TableError::Timeout { .. } => Status::deadline_exceeded(e.to_string()),
            TableError::ShuttingDown => Status::unavailable(e.to_string()),
            TableError::Corrupt(_) => Status::data_loss(e.to_string()),
        }
    }

    /// An insert that stored nothing, as a status; refusals are counted.
    fn insert_status(&self, e: InsertError) -> Status {
        match e {
            InsertError::LogDown(e) => {
                self.metrics.reject(RejectReason::Unavailable);
                Status::unavailable(e.to_string())
            }
            InsertError::NotDurable(e) => {
                self.metrics.reject(RejectReason::Unavailable);
                Status::unavailable(format!(
                    "{e}; nothing stored, so not acknowledged: send the batch again"
                ))
            }
            InsertError::Table(e) => self.status(e),
        }
    }

    async fn insert(&self, request: pb::InsertRequest) -> Result<pb::InsertAck, Status> {
        let table = self.table_or_status(&request.table)?;
        let batch = request.batch.ok_or_else(|| {
            self.reject(&BatchError::new(
                RejectReason::BadRequest,
                "batch",
                "missing",
            ))
        })?;
        self.accept(
            self.limits
                .check_batch("batch.actions", batch.actions.len()),
        )?;
        let batch = self.accept(wire::batch_from_wire(batch).map_err(|e| e.within("batch")))?;
        let prepared = PreparedBatch::new(batch);
        let done = self
            .begin_insert(table, prepared, Transport::Grpc, Admission::Timeout)
            .await
            .map_err(|e| self.insert_status(e))?
            .finish()
            .await
            .map_err(|e| self.insert_status(e))?;
        Ok(pb::InsertAck {
            batch_id: request.batch_id,
            inserted: done.inserted,
            table_size: done.size,
        })
    }
}

/// The tonic service. Cheap to clone.
#[derive(Debug, Clone)]
pub(crate) struct ReplayService {
    state: Arc<State>,
}

impl ReplayService {
    /// A service over `state`.
    pub(crate) fn new(state: Arc<State>) -> Self {
        Self { state }
    }
}

type AckStream = Pin<Box<dyn Stream<Item = Result<pb::InsertAck, Status>> + Send>>;

#[tonic::async_trait]
impl pb::replay_server::Replay for ReplayService {
    type InsertStream = AckStream;

    async fn insert(
        &self,
        request: Request<Streaming<pb::InsertRequest>>,
    ) -> Result<Response<AckStream>, Status> {
        let mut incoming = request.into_inner();
        let (tx, rx) = mpsc::channel(16);
        let state = self.state.clone();
        self.state.tasks.spawn(async move {
            loop {
                let next = tokio::select! {
                    next = incoming.message() => next,
                    _ = state.shutdown.wait() => {
                        let _ = tx.send(Err(Status::unavailable("the replay server is shutting down"))).await;
                        break;
                    }
                };
                let request = match next {
                    Ok(Some(request)) => request,
                    Ok(None) => break,
                    Err(status) => {
                        // tonic refuses messages above the size limit
                        // before our code sees them.
                        let status = if status.message().contains("too large") {
                            state.metrics.reject(RejectReason::Oversized);
                            Status::resource_exhausted(status.message().to_owned())
                        } else {
                            status
                        };
                        let _ = tx.send(Err(status)).await;
                        break;
                    }
                };
                let outcome = state.insert(request).await;
                let failed = outcome.is_err();
                if tx.send(outcome).await.is_err() || failed {
                    break;
                }
            }
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(rx))))
    }

    async fn sample(
        &self,
        request: Request<pb::SampleRequest>,
    ) -> Result<Response<pb::SampleResponse>, Status> {
        let (state, r) = (&self.state, request.into_inner());
        let table = state.table_or_status(&r.table)?;
        state.accept(state.limits.check_sample(r.batch_size as usize))?;
        if !r.beta.is_finite() {
            return Err(state.reject(&BatchError::new(
                RejectReason::BadRequest,
                "beta",
                format!("{} is not in [0, 1]", r.beta),
            )));
        }
        let wait = match r.timeout_ms {
            0 => state.limits.sample_timeout,
            ms => Duration::from_millis(u64::from(ms)).min(MAX_SAMPLE_WAIT),
        };
        let sample = table
            .sample(
                r.batch_size as usize,
                f64::from(r.beta),
                wait,
                &state.shutdown,
            )
            .await
            .map_err(|e| state.status(e))?;
        Ok(Response::new(wire::sample_to_wire(sample)))
    }

    async fn update_priorities(
        &self,
        request: Request<pb::UpdatePrioritiesRequest>,
    ) -> Result<Response<pb::UpdatePrioritiesResponse>, Status> {
        let (state, r) = (&self.state, request.into_inner());
        let table = state.table_or_status(&r.table)?;
        state.accept(state.limits.check_update(r.keys.len()))?;
        let done = table
            .update_priorities(&r.keys, &r.priorities)
            .map_err(|e| state.status(e))?;
        Ok(Response::new(pb::UpdatePrioritiesResponse {
            updated: done.updated,
            ignored: done.ignored,
        }))
    }

    async fn info(
        &self,
        request: Request<pb::InfoRequest>,
    ) -> Result<Response<pb::TableInfo>, Status> {
        let (state, r) = (&self.state, request.into_inner());
        let mut info = state.table_or_status(&r.table)?.stats().into_info();
        info.rejections_total = state
            .metrics
            .rejections()
            .into_iter()
            .filter(|(_, n)| *n > 0)
            .map(|(reason, n)| (reason.to_owned(), n))
            .collect();
        info.last_snapshot_unix_ms =
            state.metrics.last_snapshot_unix_ms.load(Ordering::SeqCst) as i64;
        Ok(Response::new(wire::table_info_to_wire(info)))
    }

    async fn snapshot(
        &self,
        _request: Request<pb::SnapshotRequest>,
    ) -> Result<Response<pb::SnapshotResponse>, Status> {
        let Some(snapshots) = self.state.snapshots.clone() else {
            return Err(Status::failed_precondition(
                "snapshots are disabled: the server has no replay.snapshot_dir",
            ));
        };
        let tables: Vec<Arc<Table>> = self.state.tables.values().cloned().collect();
        let written = tokio::task::spawn_blocking(move || snapshots.write(&tables))
            .await
            .map_err(|e| Status::internal(format!("snapshot task failed: {e}")))?
            .map_err(|e| Status::internal(e.to_string()))?;
        Ok(Response::new(pb::SnapshotResponse {
            path: written.path.display().to_string(),
            items: written.items,
            bytes: written.bytes,
            duration_seconds: written.duration.as_secs_f64(),
        }))
    }

    async fn join_actor(
        &self,
        request: Request<pb::JoinActorRequest>,
    ) -> Result<Response<pb::JoinActorResponse>, Status> {
        let name = request.into_inner().name;
        let (index, joined) = self.state.roster.join(&name).map_err(|e| {
            self.state
                .reject(&BatchError::new(RejectReason::BadRequest, "name", e))
        })?;
        tracing::info!(%name, index, joined, "an actor joined");
        Ok(Response::new(pb::JoinActorResponse { index, joined }))
    }
}
