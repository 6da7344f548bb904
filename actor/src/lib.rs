//! Actors: the processes that turn simulator steps into prioritized n-step
//! transitions for the replay server.
//!
//! An [`Actor`] owns a [`VecEnv`] (M environments of one scenario stepped in
//! parallel with rayon, their observations in one contiguous buffer) and
//! per environment an [`NStepAssembler`]. Each [`Actor::step`] makes one
//! batched call of an [`ActionValues`] (the Q-network, supplied by the
//! caller so it can swap weights between steps), chooses actions with
//! [`EpsilonGreedy`] (epsilon per environment from the Ape-X [`Ladder`] over
//! every environment of every actor, an absorbing *go* explored once per
//! episode, or greedy in evaluation [`Mode`]), steps the environments and
//! assembles n-step transitions over k-step actions (windows cut before an
//! exploratory action) with initial priorities from its own Q estimates; a [`BatchBuilder`] packs them into
//! [`TransitionBatch`](crossroads_types::TransitionBatch)es.
//! [`Actor::run`] is the acting loop. A [`Pusher`] delivers batches over
//! gRPC or iceoryx2 ([`PushConfig`]) from a bounded [`PushBuffer`] (oldest
//! dropped first), retrying with backoff and reconnecting.
//! [`EpisodeStats`] sums episode ends for evaluation reports;
//! [`ActorMetrics`] are the `crossroads_actor_*` metrics. A
//! [`WeightsSubscription`] receives the learner's weights (gRPC stream or
//! iceoryx2) into a `crossroads_transport::WeightsSlot`; a [`LiveNetwork`]
//! applies the newest between steps. [`start`] / [`run`] put it all
//! together for one actor process under one shutdown signal
//! ([`ActorParts`] is the actor it assembles, for benches).
//! Configuration: the `[actor]` section
//! ([`crossroads_config::ActorConfig`]) through
//! [`ActorSettings::from_config`] and [`resolve_index`].

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
mod vec_env;
mod weights;
mod worker;

pub use actor::{
    Actor, ActorSettings, ActorShield, GoForks, RunReport, StepSummary, actor_seed, hostname,
    resolve_index, resolve_observation,
};
pub use buffer::PushBuffer;
pub use error::ActorError;
pub use exploration::{AbsorbingGo, EpsilonGreedy, Ladder, Mode, epsilon_ladder};
pub use metrics::ActorMetrics;
pub use nstep::{
    BatchBuilder, EncodedObs, FALLBACK_PRIORITY, NStepAssembler, NStepTransition, ObsRef,
};
pub use process::{ActorParts, DRAIN, RunningActor, run, start, start_with_max_steps};
pub use push::{PushConfig, Pusher};
pub use stats::EpisodeStats;
pub use values::{ActionValues, ValuesError, argmax, max_value};
pub use vec_env::{EnvStep, EpisodeEnd, VecEnv};
pub use weights::{LiveNetwork, WeightsSubscription};
