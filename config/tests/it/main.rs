//! The configuration schema and its layered loading, as a role loads it.

mod config;
