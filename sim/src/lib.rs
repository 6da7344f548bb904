//! The intersection simulator: pure Rust, no learning and no networking.
//!
//! Its content (road model, traffic, ego dynamics, observations, action sets,
//! the TTC baseline) lands with issue 3; until then the crate is empty.
