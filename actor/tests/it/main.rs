//! Integration tests of crossroads-actor, one binary.

mod actor;
mod nstep;
mod push;
mod util;
mod values;
mod weights;
