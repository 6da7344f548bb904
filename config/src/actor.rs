//! `[actor]`: the actor processes' environments, exploration, n-step
//! assembly and transport, with Ape-X's defaults.

use serde::{Deserialize, Serialize};

use super::Checks;

/// How an actor sends its batches to the replay server.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum ActorTransport {
    /// gRPC streaming insert to `transport.replay_endpoint`, any host.
    #[default]
    Grpc,
    /// iceoryx2 shared memory (`transport.shm_prefix`), the replay
    /// server's host only.
    Shm,
}

/// An actor process (`crossroads actor`): M environments of `[sim]`'s scenario,
/// one batched forward pass per step, epsilon-greedy exploration from the
/// Ape-X ladder, n-step transitions pushed in batches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ActorConfig {
    /// Environments stepped in parallel per process (M). 1 to 4096.
    pub envs: usize,
    /// Transitions (decisions, not simulation steps) summed into one
    /// n-step return. 1 to 64.
    pub n_step: u32,
    /// Discount per simulation step; a k-step action is discounted by
    /// gamma^k. In (0, 1].
    pub gamma: f64,
    /// Reward of a collision in training, replacing the scenario's (the
    /// paper's -10). Unset: the scenario's. Finite and at most 0.
    pub collision_reward: Option<f64>,
    /// Transitions per pushed batch. 1 to 16384 (and at most the replay
    /// server's `replay.max_batch_transitions`).
    pub batch_size: usize,
    /// This actor's index i among `count`, for the epsilon ladder and its
    /// seeds. When unset (and no `CROSSROADS_ACTOR__INDEX` variable sets
    /// it, as for every key): a training actor asks the replay server for
    /// one by its host name (`JoinActor`, in order of first request, stable
    /// per name) and takes it modulo `count`, as scaled compose services and
    /// Kubernetes Deployments need; an evaluating actor uses 0.
    pub index: Option<u32>,
    /// Number of actors N in the run (`crossroads train` starts this
    /// many). 1 to 256.
    pub count: u32,
    /// Base seed of the run; each actor derives its own from it and its
    /// index, each environment its episodes' seeds from that.
    pub seed: u64,
    /// Ape-X ladder: eps_i = epsilon_base^(1 + epsilon_alpha i / (N - 1)).
    /// In [0, 1].
    pub epsilon_base: f64,
    /// Ape-X ladder exponent (7). At least 0.
    pub epsilon_alpha: f64,
    /// Whether the ladder's N counts every environment of every actor
    /// (Ape-X's acting copies: environment e of actor i is rung
    /// i * envs + e of count * envs) rather than actor processes (every
    /// environment of actor i on rung i of count; with 2 actors, 0.4 and
    /// 0.00066 and nothing between).
    pub ladder_over_envs: bool,
    /// Where *go* ends the episode (TTG, Creep): random actions exclude
    /// it and it is explored once per episode at most, at a step drawn
    /// uniformly over the step limit. Off: uniformly random actions, which
    /// end most exploring episodes within a few decisions.
    pub explore_go_once: bool,
    /// Temporally extended exploration by intents (after Dabney et al.
    /// 2021's ez-greedy): where an environment's epsilon fires and it
    /// holds no intent, it draws one of wait, creep and go uniformly, and
    /// a hold, geometric with mean `intent_hold` decisions (a go: to the
    /// episode's end, as an absorbing go); for the hold every decision is
    /// the action that carries the intent out at the ego's speed
    /// (`ActionSet::encode`). Uniform random accelerations rarely string
    /// together the seconds of accelerating a Sequential crossing takes,
    /// and drift the ego into the lanes instead (an actor test measures
    /// both). Creep-and-Go and Sequential actions only. Off: one random
    /// action per exploring decision.
    pub explore_intents: bool,
    /// Mean hold of an exploring intent, in decisions
    /// (`explore_intents`). 1 to 1000.
    pub intent_hold: f64,
    /// Whether an n-step window is cut (bootstrapped) before an exploratory
    /// action, so that returns follow the greedy policy. Off: returns sum
    /// over whatever was taken.
    pub cut_at_exploration: bool,
    /// Act on the environments in two halves, one half's forward pass
    /// beside the other half's simulation step, so the simulators and the
    /// network do not wait for each other: where the forward pass runs in
    /// plain Rust (an MLP in f32) and there are at least 2 environments. A
    /// libtorch forward pass (conv) keeps one lane: at half the batch it
    /// costs more than the overlap saves. Off: one forward pass for all,
    /// then one step for all.
    pub pipeline: bool,
    /// Demonstrations early in training: this many environments of each
    /// actor (its last ones, the least exploring of the ladder) follow
    /// `demo_policy` instead of the network for the actor's first
    /// `early_demo_steps` steps, then explore like the rest. Their
    /// transitions enter the replay like any others; their n-step windows
    /// are cut where the rule's action is not the network's greedy one, so
    /// the returns stay those of the greedy policy. They give an occlusion
    /// network the safe *go*s at a clear view that its own exploration
    /// rarely reaches (reports/time-to-target/NOTES.md). 0: none. At most
    /// `envs`.
    pub early_demo_envs: usize,
    /// Steps of each actor (one decision of each of its environments)
    /// during which the demonstrating environments follow `demo_policy`.
    /// At least 1 when `early_demo_envs` is set.
    pub early_demo_steps: u64,
    /// The rule the demonstrating environments follow, as `crossroads eval
    /// --policy` reads it: `ttc:<seconds>` or `ttc-creep:<seconds>`.
    /// Needed when `early_demo_envs` is set.
    pub demo_policy: Option<String>,
    /// The safety shield in the training loop: every environment acts
    /// through it. A vetoed *go* executes as the network's best one-step
    /// alternative (wait or creep), and that executed action is what its
    /// n-step window records; beside it the vetoed *go* is stored as a
    /// transition of its own, with the executed step's outcome less
    /// `veto_cost` (the shielded task's *go*, after Alshiekh et al. 2018),
    /// so Q(go) where the shield vetoes learns the alternative's value less
    /// the cost instead of staying unvisited. The value is the shield's
    /// assumptions as `crossroads eval --shield` reads them (`default`,
    /// `assume=human`, `margin_s=0.3`, ...); the run's evaluations and its
    /// `best/` are then behind the same shield. TTG and Creep-and-Go
    /// actions only. Unset: no shield.
    pub shield: Option<String>,
    /// What a vetoed *go* costs in its stored transition, in the reward's
    /// units (a success is worth 1). At least 0.
    pub veto_cost: f64,
    /// Counterfactual *go* labels: at each training decision that is not a
    /// *go*, with this probability the environment is forked (the same
    /// present, hidden cars included, another future) and a *go* run to
    /// its end in the fork; that *go*, from the decision's observation, is
    /// stored as a transition of its own with the fork's return (a *go*
    /// ends the episode, so nothing is bootstrapped). Q(go) then learns
    /// from outcomes where the policy rarely goes: the shortage that makes
    /// a creep network undervalue safe *go*s and go where the present has
    /// already decided a collision (reports/occlusion-ladder). TTG and
    /// Creep-and-Go actions only. 0: none. In [0, 1].
    pub go_forks: f64,
    /// Greedy evaluation: no exploration, no transitions pushed; episodes
    /// are reported to the metrics (and the log: each at debug level,
    /// outcome rates every 30 s at info).
    pub eval: bool,
    /// `grpc` or `shm`.
    pub transport: ActorTransport,
    /// How newer weights reach the actor: `grpc` (the learner's
    /// SubscribeWeights stream at `transport.learner_endpoint`, any host)
    /// or `shm` (the learner's iceoryx2 broadcast, its host only). Unset:
    /// the same as `transport`.
    pub weights: Option<ActorTransport>,
    /// Batches kept while the replay server is unreachable; beyond it the
    /// oldest are dropped (and counted). At least 1.
    pub buffer_batches: usize,
    /// Batches sent and not yet acknowledged over gRPC. 1 to 1024.
    pub in_flight: usize,
}

impl Default for ActorConfig {
    fn default() -> Self {
        Self {
            envs: 8,
            n_step: 3,
            gamma: 0.99,
            collision_reward: None,
            batch_size: 128,
            index: None,
            count: 1,
            seed: 1,
            epsilon_base: 0.4,
            epsilon_alpha: 7.0,
            ladder_over_envs: true,
            explore_go_once: true,
            explore_intents: false,
            intent_hold: 10.0,
            cut_at_exploration: true,
            pipeline: true,
            early_demo_envs: 0,
            early_demo_steps: 0,
            demo_policy: None,
            shield: None,
            veto_cost: 0.0,
            go_forks: 0.0,
            eval: false,
            transport: ActorTransport::Grpc,
            weights: None,
            buffer_batches: 256,
            in_flight: 4,
        }
    }
}

impl ActorConfig {
    /// How weights arrive: `weights`, else `transport`.
    pub fn weights_transport(&self) -> ActorTransport {
        self.weights.unwrap_or(self.transport)
    }

    /// Range and relation checks, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = Checks::new("actor");
        problems.within("envs", self.envs, 1..=4096);
        problems.within("n_step", self.n_step, 1..=64);
        problems.check(
            self.gamma > 0.0 && self.gamma <= 1.0,
            "gamma",
            format!("must be in (0, 1], got {}", self.gamma),
        );
        if let Some(r) = self.collision_reward {
            problems.check(
                r.is_finite() && r <= 0.0,
                "collision_reward",
                format!("must be finite and at most 0, got {r}"),
            );
        }
        problems.within("batch_size", self.batch_size, 1..=16_384);
        problems.within("count", self.count, 1..=256);
        if let Some(index) = self.index {
            problems.check(
                index < self.count,
                "index",
                format!("must be below actor.count ({}), got {index}", self.count),
            );
        }
        problems.check(
            (0.0..=1.0).contains(&self.epsilon_base),
            "epsilon_base",
            format!("must be in [0, 1], got {}", self.epsilon_base),
        );
        problems.check(
            self.epsilon_alpha >= 0.0 && self.epsilon_alpha.is_finite(),
            "epsilon_alpha",
            format!("must be finite and at least 0, got {}", self.epsilon_alpha),
        );
        problems.check(
            self.buffer_batches >= 1,
            "buffer_batches",
            "must be at least 1".to_owned(),
        );
        problems.within("in_flight", self.in_flight, 1..=1024);
        problems.check(
            (1.0..=1000.0).contains(&self.intent_hold),
            "intent_hold",
            format!("must be in [1, 1000], got {}", self.intent_hold),
        );
        problems.check(
            self.veto_cost.is_finite() && self.veto_cost >= 0.0,
            "veto_cost",
            format!("must be finite and at least 0, got {}", self.veto_cost),
        );
        problems.check(
            (0.0..=1.0).contains(&self.go_forks),
            "go_forks",
            format!("must be in [0, 1], got {}", self.go_forks),
        );
        if self.early_demo_envs > 0 {
            problems.check(
                self.early_demo_envs <= self.envs,
                "early_demo_envs",
                format!(
                    "must be at most actor.envs ({}), got {}",
                    self.envs, self.early_demo_envs
                ),
            );
            problems.check(
                self.early_demo_steps >= 1,
                "early_demo_steps",
                "must be at least 1 when actor.early_demo_envs is set".to_owned(),
            );
            problems.check(
                self.demo_policy.is_some(),
                "demo_policy",
                "is needed when actor.early_demo_envs is set (e.g. \"ttc-creep:3.25\")".to_owned(),
            );
        }
        problems.into_vec()
    }
}
