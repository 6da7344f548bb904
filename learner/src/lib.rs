//! The learner: dueling double DQN training, weight broadcast, checkpoints.
//! Never steps a simulator.
//!
//! Its content lands with issue 5; until then the crate is empty.
