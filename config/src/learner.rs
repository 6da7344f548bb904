//! `[learner]`: the learner's network, optimizer, targets, weight broadcast
//! and checkpoints, with the paper's (and DQN's) defaults.

use std::net::SocketAddr;
use std::path::PathBuf;

use crossroads_types::TrunkKind;
use serde::{Deserialize, Serialize};

use super::Checks;

/// Which optimizer trains the online network.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum OptimizerKind {
    /// RMSProp as in the paper (Mnih et al. 2013/2015): uncentered, no
    /// momentum.
    #[default]
    Rmsprop,
    /// Adam (Kingma and Ba), with bias correction.
    Adam,
}

/// How the target network follows the online one.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum TargetUpdate {
    /// Copied every `target_period` updates (DQN).
    #[default]
    Period,
    /// Moved a fraction `target_tau` towards the online network after every
    /// update (Polyak averaging).
    Soft,
}

/// The learner (`crossroads learner`): dueling double DQN with n-step
/// returns, trained from the replay server, publishing weights and keeping
/// checkpoints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct LearnerConfig {
    /// gRPC address of the learner service (weights, checkpoints, status);
    /// port 0 picks a free port.
    pub listen: SocketAddr,
    /// Trunk of the dueling network: `mlp` or `conv`.
    pub trunk: TrunkKind,
    /// For `mlp` the hidden widths; for `conv` the channels of each 3x3
    /// convolution, then the width of the fully connected layer.
    pub hidden: Vec<u32>,
    /// Seed of the network's initial weights.
    pub seed: u64,
    /// Transitions per update. 1 to 65536.
    pub batch_size: u32,
    /// `rmsprop` (the paper) or `adam`.
    pub optimizer: OptimizerKind,
    /// Step size. Above 0.
    pub learning_rate: f64,
    /// RMSProp: decay of the squared-gradient average (DQN: 0.95). In
    /// [0, 1).
    pub rmsprop_decay: f64,
    /// RMSProp: added to the root of the average (DQN: 0.01). Above 0.
    pub rmsprop_eps: f64,
    /// Adam: decay of the first moment. In [0, 1).
    pub adam_beta1: f64,
    /// Adam: decay of the second moment. In [0, 1).
    pub adam_beta2: f64,
    /// Adam: added to the root of the second moment. Above 0.
    pub adam_eps: f64,
    /// Largest global L2 norm of the gradient; larger ones are scaled down
    /// to it. 0 turns clipping off.
    pub max_grad_norm: f64,
    /// Huber loss: quadratic within this distance, linear beyond. Above 0.
    /// The default (20) keeps every TD error of the paper's rewards (+1,
    /// -10, -0.01 a step: returns and consistent Q-values within [-11, 1])
    /// in the quadratic part, so Q estimates the mean return; with delta 1
    /// a collision's error (~10) falls in the linear part and Q(go) drifts
    /// towards a median, preferring *go* up to ~50 % collision risk where
    /// the break-even against a timeout is ~18 %. Raise it with
    /// `actor.collision_reward`.
    pub huber_delta: f64,
    /// `period` (hard copy) or `soft` (Polyak) target updates.
    pub target_update: TargetUpdate,
    /// Updates between hard target copies. At least 1.
    pub target_period: u64,
    /// Updates of an early phase with its own learning rate and target
    /// period (`early_learning_rate`, `early_target_period`): bold steps
    /// while the network learns the most, the main settings after. 0 (the
    /// default) has no early phase.
    pub early_updates: u64,
    /// Learning rate of the first `early_updates` updates; unset keeps
    /// `learning_rate`. Above 0.
    pub early_learning_rate: Option<f64>,
    /// Target period of the first `early_updates` updates; unset keeps
    /// `target_period`. At least 1.
    pub early_target_period: Option<u64>,
    /// Soft update fraction per update. In (0, 1].
    pub target_tau: f64,
    /// Multiplies the loss weight of exact *go* labels: items whose action
    /// is the action set's absorbing *go* (ttg, creep) with discount 0, so
    /// nothing in their target is bootstrapped. Counterfactual gos
    /// (`actor.go_forks`) are among them. Priorities are unchanged. 1 (the
    /// default) weighs them as any item; the sequential set has no such
    /// *go* and takes only 1. Finite, above 0.
    pub go_label_weight: f64,
    /// Importance-sampling exponent at the start of the run (Ape-X: 0.4).
    /// In [0, 1].
    pub importance_beta: f64,
    /// Importance-sampling exponent reached by the end of the anneal
    /// (Schaul et al.: 1, which undoes the sampling bias of prioritized
    /// replay once Q settles). In [0, 1].
    pub importance_beta_final: f64,
    /// Updates over which beta moves linearly from `importance_beta` to
    /// `importance_beta_final`; 0 anneals over `max_updates` (or keeps
    /// `importance_beta` when that is 0 too).
    pub importance_beta_updates: u64,
    /// Added to |TD error| to form the new priority, so no item becomes
    /// unsampleable. At least 0.
    pub priority_eps: f64,
    /// Sampled batches kept ready in the background, so the learner rarely
    /// waits on the network. 1 to 64.
    pub prefetch: u32,
    /// Updates between weight publications (iceoryx2 and gRPC). At least 1.
    pub publish_every: u64,
    /// Whether to publish weights over iceoryx2 shared memory for actors on
    /// this host (beside the gRPC stream).
    pub shm_publish: bool,
    /// Where checkpoints are written, listed and restored from; none turns
    /// checkpoints (and their API) off.
    pub checkpoint_dir: Option<PathBuf>,
    /// Updates between checkpoints; 0 writes them only on shutdown and on
    /// request.
    pub checkpoint_every: u64,
    /// Newest checkpoints kept (the best by evaluation is kept besides).
    /// At least 1.
    pub checkpoint_keep: u32,
    /// Evaluation metric that picks the best checkpoint (higher is
    /// better): `mean_return` (the task's objective, as `train` reports it
    /// and keeps its `best/` weights by), or another reported metric such
    /// as `success_rate`.
    pub best_metric: String,
    /// Whether to resume from the newest checkpoint at start.
    pub resume: bool,
    /// Removed: the token is no longer written in the config. It lives in
    /// a file (`transport.auth.token_file`) or the environment
    /// (`CROSSROADS_TOKEN`) and guards both services. Kept only so that a
    /// file that still sets it is refused with that advice.
    #[serde(skip_serializing)]
    #[schemars(skip)]
    pub api_token: Option<String>,
    /// Stop after this many updates (counted over the run's life, so a
    /// resumed run stops at the same step); 0 trains until shutdown.
    pub max_updates: u64,
}

impl Default for LearnerConfig {
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 50052)),
            trunk: TrunkKind::Mlp,
            hidden: vec![256, 256],
            seed: 1,
            batch_size: 64,
            optimizer: OptimizerKind::Rmsprop,
            learning_rate: 2.5e-4,
            rmsprop_decay: 0.95,
            rmsprop_eps: 0.01,
            adam_beta1: 0.9,
            adam_beta2: 0.999,
            adam_eps: 1.5e-4,
            max_grad_norm: 10.0,
            huber_delta: 20.0,
            target_update: TargetUpdate::Period,
            target_period: 2_500,
            target_tau: 0.005,
            go_label_weight: 1.0,
            early_updates: 0,
            early_learning_rate: None,
            early_target_period: None,
            importance_beta: 0.4,
            importance_beta_final: 1.0,
            importance_beta_updates: 0,
            priority_eps: 1e-6,
            prefetch: 4,
            publish_every: 50,
            shm_publish: true,
            checkpoint_dir: None,
            checkpoint_every: 10_000,
            checkpoint_keep: 3,
            best_metric: "mean_return".to_owned(),
            resume: true,
            api_token: None,
            max_updates: 0,
        }
    }
}

impl LearnerConfig {
    /// Range and relation checks, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = Checks::new("learner");
        problems.check(
            !self.hidden.is_empty() && self.hidden.iter().all(|&h| (1..=65_536).contains(&h)),
            "hidden",
            format!(
                "must be a non-empty list of widths between 1 and 65536, got {:?}",
                self.hidden
            ),
        );
        problems.check(
            self.trunk != TrunkKind::Conv || self.hidden.len() >= 2,
            "hidden",
            format!(
                "a conv trunk needs the channels of at least one convolution and then the fully connected width, got {:?}",
                self.hidden
            ),
        );
        problems.within("batch_size", self.batch_size, 1..=65_536);
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let fraction = |v: f64| (0.0..1.0).contains(&v);
        for (key, v) in [
            ("learning_rate", self.learning_rate),
            ("rmsprop_eps", self.rmsprop_eps),
            ("adam_eps", self.adam_eps),
            ("huber_delta", self.huber_delta),
            ("go_label_weight", self.go_label_weight),
        ] {
            problems.check(
                positive(v),
                key,
                format!("must be finite and above 0, got {v}"),
            );
        }
        for (key, v) in [
            ("rmsprop_decay", self.rmsprop_decay),
            ("adam_beta1", self.adam_beta1),
            ("adam_beta2", self.adam_beta2),
        ] {
            problems.check(fraction(v), key, format!("must be in [0, 1), got {v}"));
        }
        problems.check(
            self.max_grad_norm.is_finite() && self.max_grad_norm >= 0.0,
            "max_grad_norm",
            format!(
                "must be finite and at least 0 (0 = no clipping), got {}",
                self.max_grad_norm
            ),
        );
        if let Some(lr) = self.early_learning_rate {
            problems.check(
                positive(lr),
                "early_learning_rate",
                format!("must be finite and above 0, got {lr}"),
            );
        }
        if let Some(period) = self.early_target_period {
            problems.check(
                period >= 1,
                "early_target_period",
                format!("must be at least 1, got {period}"),
            );
        }
        problems.check(
            self.target_period >= 1,
            "target_period",
            "must be at least 1".to_owned(),
        );
        problems.check(
            self.target_tau > 0.0 && self.target_tau <= 1.0,
            "target_tau",
            format!("must be in (0, 1], got {}", self.target_tau),
        );
        for (key, v) in [
            ("importance_beta", self.importance_beta),
            ("importance_beta_final", self.importance_beta_final),
        ] {
            problems.check(
                (0.0..=1.0).contains(&v),
                key,
                format!("must be in [0, 1], got {v}"),
            );
        }
        problems.check(
            self.priority_eps.is_finite() && self.priority_eps >= 0.0,
            "priority_eps",
            format!("must be finite and at least 0, got {}", self.priority_eps),
        );
        problems.within("prefetch", self.prefetch, 1..=64);
        problems.check(
            self.publish_every >= 1,
            "publish_every",
            "must be at least 1".to_owned(),
        );
        problems.check(
            self.checkpoint_keep >= 1,
            "checkpoint_keep",
            "must be at least 1".to_owned(),
        );
        problems.check(
            !self.best_metric.is_empty(),
            "best_metric",
            "must name an evaluation metric".to_owned(),
        );
        problems.check(
            self.api_token.is_none(),
            "api_token",
            "was removed, since a secret does not belong in a config file: write the token \
             into a file and name it in transport.auth.token_file, or set CROSSROADS_TOKEN; \
             it now guards the replay's and the learner's state-changing calls"
                .to_owned(),
        );
        problems.into_vec()
    }
}
