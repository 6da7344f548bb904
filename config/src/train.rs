//! `[train]`: how `crossroads train` runs a whole training job on one
//! machine: how its actors reach the replay, greedy
//! evaluations, the time budget and the target that counts as reached.

use serde::{Deserialize, Serialize};

use super::{ActorTransport, Checks};

/// `crossroads train`: the replay, the learner and `actor.count` actor processes
/// on this machine. The update budget is `learner.max_updates`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// How the actors push transitions and get weights: `shm` (iceoryx2,
    /// the local transport) or `grpc`.
    pub transport: ActorTransport,
    /// Learner updates between greedy evaluations. At least 1.
    pub eval_every: u64,
    /// Trials per periodic evaluation (the same seeded trials each time).
    /// Keep it small (1,000 takes seconds): evaluations share the cores
    /// with training, and `confirm_trials` and `reproduce` measure the
    /// 10,000-trial figures. At least 1.
    pub eval_trials: u64,
    /// Largest share of wall time the periodic evaluations may take: the
    /// next one waits (past `eval_every`) until the last one's duration is
    /// at most this share of the time since it began. A re-measure on
    /// `confirm_trials` (rare: a new best) is not counted. In (0, 1].
    pub eval_share: f64,
    /// Seed of the evaluation trials (kept apart from the actors' seeds).
    pub eval_seed: u64,
    /// Trials that confirm a periodic evaluation that met the target (the
    /// paper evaluates on 10,000). At least 1.
    pub confirm_trials: u64,
    /// Success rate that counts as reached (with `target_collision`), as a
    /// fraction; 0 turns the target off. In [0, 1].
    pub target_success: f64,
    /// Largest collision rate that counts as reached, as a fraction. In
    /// [0, 1].
    pub target_collision: f64,
    /// Largest mean time to goal (successful runs) that counts as reached,
    /// seconds; 0 sets no bound. At least 0.
    pub target_time_s: f64,
    /// Stop once the target is confirmed.
    pub stop_at_target: bool,
    /// Wall-clock budget in minutes; 0 sets none (the update budget and
    /// Ctrl-C still stop the run). At least 0.
    pub max_minutes: f64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            transport: ActorTransport::Shm,
            eval_every: 2_000,
            eval_trials: 1_000,
            eval_share: 0.2,
            eval_seed: 20_180_521,
            confirm_trials: 10_000,
            target_success: 0.0,
            target_collision: 0.0,
            target_time_s: 0.0,
            stop_at_target: false,
            max_minutes: 0.0,
        }
    }
}

impl TrainConfig {
    /// Range checks, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = Checks::new("train");
        for (key, v) in [
            ("eval_every", self.eval_every),
            ("eval_trials", self.eval_trials),
            ("confirm_trials", self.confirm_trials),
        ] {
            problems.check(v >= 1, key, "must be at least 1".to_owned());
        }
        for (key, v) in [
            ("target_success", self.target_success),
            ("target_collision", self.target_collision),
        ] {
            problems.check(
                (0.0..=1.0).contains(&v),
                key,
                format!("must be a fraction in [0, 1], got {v}"),
            );
        }
        problems.check(
            self.eval_share > 0.0 && self.eval_share <= 1.0,
            "eval_share",
            format!("must be in (0, 1], got {}", self.eval_share),
        );
        for (key, v) in [
            ("target_time_s", self.target_time_s),
            ("max_minutes", self.max_minutes),
        ] {
            problems.check(
                v >= 0.0 && v.is_finite(),
                key,
                format!("must be finite and at least 0, got {v}"),
            );
        }
        problems.into_vec()
    }

    /// Whether an evaluation meets the target (never when it is off).
    pub fn met(&self, success: f64, collision: f64, mean_time_s: Option<f64>) -> bool {
        self.target_success > 0.0
            && success >= self.target_success
            && collision <= self.target_collision
            && (self.target_time_s <= 0.0 || mean_time_s.is_some_and(|t| t <= self.target_time_s))
    }
}
