//! Integration tests of the learner: the update's arithmetic, learning a
//! known MDP, checkpoints and exact resume, the gRPC service over a real
//! loopback socket against a real replay server, and the learner's device
//! (`runtime.device`).

mod checkpoints;
mod device;
mod python;
mod server;
mod training;

use crossroads_config::SimConfig;
use crossroads_model::{NetworkSpec, ObservationLayout, TrunkKind};
use crossroads_types::{ObservationEncoding, TransitionBatch};

/// A network over `n` one-hot states.
pub fn toy_spec(n: i64, actions: i64, hidden: Vec<i64>) -> NetworkSpec {
    NetworkSpec {
        observation: ObservationLayout {
            kind: "toy".to_owned(),
            channels: 1,
            rows: 1,
            cols: n,
            extra: 0,
        },
        action_set: "toy".to_owned(),
        num_actions: actions,
        trunk: TrunkKind::Mlp,
        hidden,
    }
}

/// An empty batch of the toy network's observations.
pub fn toy_batch(spec: &NetworkSpec) -> TransitionBatch {
    TransitionBatch::new(
        spec.observation.clone(),
        spec.num_actions as u32,
        ObservationEncoding::DenseF32,
    )
}

/// The simulator's layout of view `kind`.
/// An MLP of 32 and 16 units on the Sequential view, scoring TTG actions.
pub fn small_mlp() -> NetworkSpec {
    NetworkSpec::new(layout("sequential"), "ttg", TrunkKind::Mlp, vec![32, 16]).expect("test setup")
}

pub fn layout(kind: &str) -> ObservationLayout {
    crossroads_sim::observation_layout(kind).expect("a view")
}

/// `sim` set to the simulator's view `kind`, as a role resolves it at
/// start (`crossroads_actor::resolve_observation`, which the learner's
/// tests do not link).
pub fn set_observation(sim: &mut SimConfig, kind: &str) {
    sim.observation = None;
    sim.resolve_layout(layout(kind)).expect("a view");
}
