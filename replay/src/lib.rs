//! Prioritized replay tables and the replay server. Never links tch.
//!
//! Its content (sum-tree tables, rate limiter, snapshots, gRPC and iceoryx2
//! ingest) lands with issue 4; until then the crate is empty.
