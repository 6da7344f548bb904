//! The one insert path of both transports (gRPC in `service`, shared
//! memory in `ingest`).
//!
//! A batch arrives validated and encoded outside any lock; its table
//! admits it ([`Table::reserve`]: the rate limiter's wait and the spec
//! check); with the write-ahead log on, the log's writer frames it, fsyncs
//! it with its group and only then stores it in the table ([`crate::wal`]);
//! the stored batch is counted here, once, for either transport, and the
//! transport acknowledges it. A batch whose record fails never enters the
//! table: it is not sampled while unacknowledged, and the actor's resend
//! stores it once. A durable batch cannot be refused anymore: its room was
//! reserved before it was logged.

use std::sync::Arc;

use crate::metrics::Transport;
use crate::service::State;
use crate::table::{Inserted, PreparedBatch, Table, TableError};
use crate::wal::{Pending, WalError};

/// How an insert waits for the rate limiter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Admission {
    /// At most the server's insert timeout, and shutdown ends the wait:
    /// the caller is told and may send again (gRPC).
    Timeout,
    /// As long as it takes, keeping the batch; once the server is shutting
    /// down, at once, whatever the limiter says (the shared-memory ingest:
    /// a batch received is stored before the last snapshot, and the
    /// publishers feel the back-pressure through their unacknowledged
    /// batches).
    Patient,
}

/// Why an insert stored nothing.
#[derive(Debug)]
pub(crate) enum InsertError {
    /// The write-ahead log failed within the last second: refused before
    /// the table was touched.
    LogDown(WalError),
    /// The table refused the batch (another spec), or its wait ended
    /// (timeout, shutdown).
    Table(TableError),
    /// The batch's log record failed: not stored, not acknowledged.
    NotDurable(WalError),
}

/// An admitted batch on its way into its table.
#[derive(Debug)]
pub(crate) struct InFlight {
    table: Arc<Table>,
    transport: Transport,
    step: Step,
}

#[derive(Debug)]
enum Step {
    /// Stored (the log is off).
    Stored(Inserted),
    /// With the log's writer, which stores it once its record is durable.
    Logging(Pending),
}

impl State {
    /// Admits `batch`, which came over `transport`, into `table` as
    /// `admission` says, then hands it to the write-ahead log, which
    /// stores it once durable, or, with the log off, stores it. Wait on
    /// the returned insert ([`InFlight::finish`], [`InFlight::try_finish`])
    /// before acknowledging.
    pub(crate) async fn begin_insert(
        &self,
        table: &Arc<Table>,
        batch: PreparedBatch,
        transport: Transport,
        admission: Admission,
    ) -> Result<InFlight, InsertError> {
        self.check_durable().map_err(InsertError::LogDown)?;
        let wait = self.limits.insert_timeout;
        let reservation = match admission {
            Admission::Timeout => table.reserve(&batch, wait, &self.shutdown).await,
            Admission::Patient => loop {
                if self.shutdown.is_triggered() {
                    break table.reserve_now(&batch);
                }
                match table.reserve(&batch, wait, &self.shutdown).await {
                    Err(TableError::Timeout { .. } | TableError::ShuttingDown) => continue,
                    reserved => break reserved,
                }
            },
        }
        .map_err(InsertError::Table)?;
        let step = match &self.wal {
            Some(wal) => Step::Logging(wal.append(reservation, batch)),
            None => Step::Stored(reservation.store(&batch)),
        };
        Ok(InFlight {
            table: table.clone(),
            transport,
            step,
        })
    }
}

impl InFlight {
    /// Waits until the batch is stored (or its record failed): what to
    /// acknowledge.
    pub(crate) async fn finish(self) -> Result<Inserted, InsertError> {
        let Self {
            table,
            transport,
            step,
        } = self;
        let stored = match step {
            Step::Stored(done) => Ok(done),
            Step::Logging(pending) => pending.durable().await,
        };
        counted(&table, transport, stored)
    }

    /// The same without an async runtime: the answer if it has come, or,
    /// with `block`, once it comes (not on an async runtime's thread);
    /// otherwise the insert back, to ask again later.
    pub(crate) fn try_finish(self, block: bool) -> Result<Result<Inserted, InsertError>, Self> {
        let Self {
            table,
            transport,
            step,
        } = self;
        let stored = match step {
            Step::Stored(done) => Ok(done),
            Step::Logging(pending) if block => pending.wait_durable(),
            Step::Logging(mut pending) => match pending.try_durable() {
                Some(stored) => stored,
                None => {
                    return Err(Self {
                        table,
                        transport,
                        step: Step::Logging(pending),
                    });
                }
            },
        };
        Ok(counted(&table, transport, stored))
    }
}

/// Counts a stored batch in its table's insert metrics, the one place
/// either transport's batches are counted: after the log holds them and
/// before they are acknowledged.
fn counted(
    table: &Table,
    transport: Transport,
    stored: Result<Inserted, WalError>,
) -> Result<Inserted, InsertError> {
    let done = stored.map_err(InsertError::NotDurable)?;
    table
        .metrics()
        .inserted(transport, u64::from(done.inserted));
    Ok(done)
}
