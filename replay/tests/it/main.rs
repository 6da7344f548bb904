//! Integration tests of crossroads-replay, one binary.

mod grpc;
mod legacy;
mod rate_limiter;
mod shm;
mod snapshot;
mod table;
mod util;
mod wal;
