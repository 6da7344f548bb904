//! Actors: vectorized environments, batched inference, exploration, n-step
//! assembly and transport of transitions to the replay server.
//!
//! Its content lands with issue 6; until then the crate is empty.
