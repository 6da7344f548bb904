//! [`Trainer`]: the online and target networks and the optimizer, and
//! [`Trainer::update`], one dueling double-DQN update on a batch.
//!
//! An update: targets under `no_grad` ([`crate::targets`]), the
//! importance-weighted Huber loss (`learner.huber_delta`), gradients as
//! fresh tensors ([`Optimizer::gradients`]: nothing to zero or accumulate),
//! an optimizer step after global-norm clipping, the new priorities
//! (`|TD error| + priority_eps`), and the target network's update: a hard
//! copy every `target_period` updates, or a Polyak step. Both networks
//! compute in the [`Precision`] the run chooses for training; their
//! variables stay f32.

use crossroads_config::{LearnerConfig, SimConfig, TargetUpdate};
use crossroads_model::{NetworkSpec, Precision, QNetwork, network_spec};
use tch::{Kind, Tensor};

use crate::LearnerError;
use crate::batch::TrainingBatch;
use crate::optimizer::{Optimizer, OptimizerConfig};
use crate::targets::{double_dqn_targets, taken, weighted_huber};

/// The hyperparameters of an update, from `[learner]`.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainerConfig {
    /// The network.
    pub spec: NetworkSpec,
    /// Seed of the initial weights.
    pub seed: u64,
    /// The optimizer.
    pub optimizer: OptimizerConfig,
    /// Global gradient-norm limit; 0 turns clipping off.
    pub max_grad_norm: f64,
    /// Huber loss threshold.
    pub huber_delta: f64,
    /// Hard copies or Polyak averaging.
    pub target_update: TargetUpdate,
    /// Updates between hard copies.
    pub target_period: u64,
    /// Polyak fraction.
    pub target_tau: f64,
    /// Added to |TD error| for the new priority.
    pub priority_eps: f64,
}

impl TrainerConfig {
    /// The trainer `[sim]` and `[learner]` describe; fails on an invalid
    /// network.
    pub fn from_config(sim: &SimConfig, c: &LearnerConfig) -> Result<Self, LearnerError> {
        Ok(Self {
            spec: network_spec(sim, c)?,
            seed: c.seed,
            optimizer: OptimizerConfig::from_config(c),
            max_grad_norm: c.max_grad_norm,
            huber_delta: c.huber_delta,
            target_update: c.target_update,
            target_period: c.target_period,
            target_tau: c.target_tau,
            priority_eps: c.priority_eps,
        })
    }
}

/// What one update measured.
#[derive(Debug, Clone, PartialEq)]
pub struct UpdateStats {
    /// Update count after this one.
    pub step: u64,
    /// Importance-weighted Huber loss.
    pub loss: f64,
    /// Mean Q(s, a) of the taken actions.
    pub q_mean: f64,
    /// Largest Q(s, a) of the taken actions.
    pub q_max: f64,
    /// Mean |TD error|.
    pub td_abs_mean: f64,
    /// Gradient norm before clipping.
    pub grad_norm: f64,
    /// New priorities, |TD error| + eps, in batch order.
    pub priorities: Vec<f32>,
}

/// The networks and optimizer of the learner. Owned by one thread.
#[derive(Debug)]
pub struct Trainer {
    config: TrainerConfig,
    online: QNetwork,
    target: QNetwork,
    optimizer: Optimizer,
    step: u64,
}

impl Trainer {
    /// Fresh networks (the target a copy of the online one) and a zero
    /// optimizer state.
    pub fn new(config: TrainerConfig) -> Result<Self, LearnerError> {
        let online = QNetwork::new(config.spec.clone(), config.seed)?;
        let mut target = QNetwork::new(config.spec.clone(), config.seed)?;
        target.copy_from(&online)?;
        let optimizer = Optimizer::new(config.optimizer, online.parameters());
        Ok(Self {
            config,
            online,
            target,
            optimizer,
            step: 0,
        })
    }

    /// The hyperparameters.
    pub fn config(&self) -> &TrainerConfig {
        &self.config
    }

    /// Updates applied (continued across checkpoints).
    pub fn step(&self) -> u64 {
        self.step
    }

    /// The network being trained.
    pub fn online(&self) -> &QNetwork {
        &self.online
    }

    /// The target network.
    pub fn target(&self) -> &QNetwork {
        &self.target
    }

    /// The optimizer.
    pub fn optimizer(&self) -> &Optimizer {
        &self.optimizer
    }

    /// Computes both networks' trunks in `precision` from now on (kept
    /// across [`Trainer::restore`]); weights and optimizer state stay fp32.
    pub fn set_precision(&mut self, precision: Precision) {
        self.online.set_precision(precision);
        self.target.set_precision(precision);
    }

    /// Replaces the whole training state (after loading a checkpoint):
    /// online and target weights, optimizer state and the update count.
    /// Checks everything before changing anything.
    pub fn restore(&mut self, state: TrainerState) -> Result<(), LearnerError> {
        let precision = self.online.precision();
        let mut online = QNetwork::new(self.config.spec.clone(), 0)?;
        online.load_safetensors(&state.online)?;
        online.set_precision(precision);
        let mut target = QNetwork::new(self.config.spec.clone(), 0)?;
        target.load_safetensors(&state.target)?;
        target.set_precision(precision);
        let mut optimizer = Optimizer::new(self.config.optimizer, online.parameters());
        let slots = relayout_slots(&online, state.optimizer);
        optimizer.load_state(slots, state.optimizer_steps)?;
        self.online = online;
        self.target = target;
        self.optimizer = optimizer;
        self.step = state.step;
        Ok(())
    }

    /// One update on `batch`, stage by stage.
    pub fn update(&mut self, batch: &TrainingBatch) -> Result<UpdateStats, LearnerError> {
        let c = &self.config;

        // Targets, without gradients: double DQN over the n-step return.
        let targets = tch::no_grad(|| -> Result<Tensor, LearnerError> {
            let q_online_next = self.online.q_values_of(&batch.next_obs)?;
            let q_target_next = self.target.q_values_of(&batch.next_obs)?;
            Ok(double_dqn_targets(
                &q_online_next,
                &q_target_next,
                &batch.rewards,
                &batch.discounts,
            ))
        })?;

        // Loss: Huber on the TD errors, weighted by importance.
        let q_sa = taken(&self.online.q_values_of(&batch.obs)?, &batch.actions);
        let loss = weighted_huber(&q_sa, &targets, &batch.weights, c.huber_delta);
        let loss_value = loss.double_value(&[]);
        if !loss_value.is_finite() {
            return Err(LearnerError::Diverged {
                step: self.step + 1,
                loss: loss_value,
            });
        }

        // Optimizer step, the gradient clipped by its global norm.
        let grads = self.optimizer.gradients(&loss)?;
        let grad_norm = self.optimizer.step(&grads, c.max_grad_norm)?;
        self.step += 1;

        // New priorities from the TD errors before the step.
        let td = (&targets - q_sa.detach()).abs();
        let priorities = Vec::<f32>::try_from(&td + c.priority_eps)?;
        let q_detached = q_sa.detach();

        // Target network: a copy every period, or a little every update.
        match c.target_update {
            TargetUpdate::Period => {
                if self.step.is_multiple_of(c.target_period) {
                    self.target.copy_from(&self.online)?;
                }
            }
            TargetUpdate::Soft => self.target.soft_update_from(&self.online, c.target_tau)?,
        }

        Ok(UpdateStats {
            step: self.step,
            loss: loss_value,
            q_mean: q_detached.mean(Kind::Float).double_value(&[]),
            q_max: q_detached.max().double_value(&[]),
            td_abs_mean: td.mean(Kind::Float).double_value(&[]),
            grad_norm,
            priorities,
        })
    }

    /// The training state as a checkpoint stores it.
    pub fn state(&self, version: u64) -> Result<TrainerState, LearnerError> {
        let (optimizer, optimizer_steps) = self.optimizer.state();
        let optimizer = relayout_slots(&self.online, optimizer);
        Ok(TrainerState {
            online: self.online.to_safetensors(version)?,
            target: self.target.to_safetensors(version)?,
            optimizer,
            optimizer_steps,
            step: self.step,
        })
    }
}

/// Optimizer state tensors (`<slot>.<variable>`) turned between the
/// network's stored layout and the weights file's, so a checkpoint's
/// optimizer state has the shapes of its weights (see
/// [`QNetwork::file_layout`]).
fn relayout_slots(net: &QNetwork, slots: Vec<(String, Tensor)>) -> Vec<(String, Tensor)> {
    slots
        .into_iter()
        .map(|(name, t)| {
            let variable = name.split_once('.').map_or("", |(_, v)| v);
            let t = net.file_layout(variable, t);
            (name, t)
        })
        .collect()
}

/// Everything needed to continue training exactly: both networks (as
/// safetensors bytes), the optimizer's state tensors and steps, and the
/// update count.
#[derive(Debug)]
pub struct TrainerState {
    /// Online network, safetensors.
    pub online: Vec<u8>,
    /// Target network, safetensors.
    pub target: Vec<u8>,
    /// Optimizer state tensors, named `<slot>.<variable>`.
    pub optimizer: Vec<(String, Tensor)>,
    /// Optimizer steps (Adam's bias correction needs them).
    pub optimizer_steps: u64,
    /// Updates applied.
    pub step: u64,
}
