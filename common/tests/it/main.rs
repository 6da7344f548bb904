//! Integration tests of crossroads-common, one binary.

mod config;
mod metrics;
mod shutdown;
