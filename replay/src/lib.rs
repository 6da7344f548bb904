//! Prioritized replay tables and the replay server. Never links tch.
//!
//! A [`Table`] keeps items (n-step transitions) in a FIFO ring with their
//! priorities in a [`SumTree`](sum_tree::SumTree) and their observations,
//! compact ([`compact`]) and shared, in an
//! [`ObservationStore`](storage::ObservationStore); a
//! [`RateLimiter`](rate_limiter::RateLimiter) decides when inserts and
//! samples may proceed. [`snapshot`] writes and restores tables atomically
//! with a checksum. The server ([`server::start`], [`server::run`]) serves
//! the tables over gRPC ([`service::ReplayService`]) and takes batches from
//! actors on the same host over iceoryx2 ([`ingest::ShmIngest`]), with the
//! `crossroads_replay_*` metrics of [`metrics`]. [`bench`](mod@bench) measures inserts,
//! samples and bytes per stored transition.

pub mod bench;
pub mod compact;
pub mod ingest;
pub mod metrics;
pub mod rate_limiter;
pub mod roster;
pub mod server;
pub mod service;
pub mod snapshot;
pub mod storage;
pub mod sum_tree;
pub mod table;

pub use metrics::{ReplayMetrics, TableMetrics};
pub use server::{RunningServer, ServerError, run, start};
pub use table::{PreparedBatch, Sample, Table, TableConfig, TableError, TableImage, TableStats};
