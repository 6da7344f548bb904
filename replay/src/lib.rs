//! Prioritized replay tables and the replay server. Never links tch.
//!
//! A [`Table`] keeps items (n-step transitions) in a FIFO ring with their
//! priorities in a [`SumTree`](sum_tree::SumTree) and their observations,
//! compact ([`compact`]) and shared, in an
//! [`ObservationStore`](storage::ObservationStore); a
//! [`RateLimiter`](rate_limiter::RateLimiter) decides when inserts and
//! samples may proceed. [`snapshot`] writes and restores tables atomically;
//! the write-ahead log ([`wal`]) makes every acknowledged insert durable
//! between snapshots. The server ([`server::start`], [`server::run`])
//! serves the tables over gRPC (`service`) and takes batches from actors on
//! its host over iceoryx2 (`ingest`), with the metrics of [`metrics`]; both
//! insert through one path (`insert`): a table [`Reservation`], the log,
//! the table. [`bench`](mod@bench) measures inserts, samples and bytes per
//! transition.
//!
//! Batches arrive validated once, as [`ValidBatch`](crossroads_types::ValidBatch)es
//! ([`PreparedBatch`] is made from one without another check). No public
//! signature has a prost type; the tonic service and ingest are private.

pub mod bench;
pub mod compact;
mod ingest;
mod insert;
pub mod metrics;
mod prepared_batch;
pub mod rate_limiter;
pub mod roster;
pub mod server;
mod service;
pub mod snapshot;
pub mod storage;
pub mod sum_tree;
pub mod table;
mod table_image;
pub mod wal;

pub use metrics::{ReplayMetrics, TableMetrics};
pub use server::{RunningServer, ServerError, run, start};
pub use table::{
    PreparedBatch, Reservation, Table, TableConfig, TableError, TableImage, TableStats,
};
