//! The dueling Q-network, in tch, shared by actors (batched inference) and
//! the learner (training).
//!
//! [`DuelingMlp`] maps a batch of flat observations to one Q-value per
//! action through a trunk of fully connected layers and two heads, value
//! V(s) and advantage A(s, a), combined as Q = V + A - mean(A) (Wang et
//! al. 2016). [`MlpSpec`] says its shape. Conv trunks, the weights format
//! and the version number arrive with the learner (issue 5).

mod dueling;

pub use dueling::{DuelingMlp, MlpSpec, ModelError};
