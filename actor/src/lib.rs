//! Actors: the processes that turn simulator steps into prioritized n-step
//! transitions for the replay server.
//!
//! An [`Actor`] owns a [`VecEnv`](crossroads_sim::VecEnv) (M environments of one scenario stepped in
//! parallel with rayon, their observations in one contiguous buffer) and
//! per environment an [`NStepAssembler`]. Each [`Actor::step`] makes one
//! batched call of an [`ActionValues`] (the Q-network, supplied by the
//! caller so it can swap weights between steps), chooses actions with
//! [`EpsilonGreedy`] (epsilon per environment from the Ape-X [`Ladder`], or
//! greedy in evaluation [`Mode`]), steps the environments and assembles
//! transitions with initial priorities; a [`BatchBuilder`] packs them.
//! [`Actor::run`] is the acting loop. A [`Pusher`] delivers batches over
//! gRPC or iceoryx2 ([`PushConfig`]) from a bounded [`PushBuffer`], retrying
//! with backoff. A [`WeightsSubscription`] receives the learner's weights; a
//! [`LiveNetwork`] applies the newest between steps. [`EpisodeStats`] sums
//! episode ends, [`ActorMetrics`] are the `crossroads_actor_*` metrics, and
//! [`start`] / [`run`] assemble one actor process under one shutdown signal
//! ([`ActorParts`], for benches), configured by the `[actor]` section
//! ([`ActorSettings::from_config`], [`resolve_index`]).

mod actor;
mod buffer;
mod error;
mod exploration;
mod metrics;
mod nstep;
mod process;
mod push;
mod stats;
mod values;
mod weights;
mod worker;

pub use actor::{
    Actor, ActorSettings, ActorShield, GoForks, RunReport, StepSummary, actor_seed, hostname,
    resolve_index, resolve_observation,
};
pub use buffer::PushBuffer;
pub use error::ActorError;
pub use exploration::{AbsorbingGo, EpsilonGreedy, Intents, Ladder, Mode, epsilon_ladder};
pub use metrics::ActorMetrics;
pub use nstep::{
    BatchBuilder, EncodedObs, FALLBACK_PRIORITY, NStepAssembler, NStepTransition, ObsRef,
};
pub use process::{ActorParts, DRAIN, RunningActor, run, start, start_with_max_steps};
pub use push::{PushConfig, Pusher};
pub use stats::EpisodeStats;
pub use values::{ActionValues, ValuesError, argmax, max_value};
pub use weights::{LiveNetwork, WeightsSubscription};
