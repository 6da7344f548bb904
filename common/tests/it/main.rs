//! Integration tests of crossroads-common, one binary.

mod metrics;
mod shutdown;
