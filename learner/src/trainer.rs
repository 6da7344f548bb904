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
//!
//! Networks, target network and optimizer state live on one device
//! ([`Trainer::new_on`]: the CPU, or CUDA device 0 for `runtime.device`);
//! each batch is moved there for its update, and what comes back (the
//! statistics, the priorities, the state a checkpoint stores) is on the
//! CPU.

use crossroads_config::{LearnerConfig, SimConfig, TargetUpdate};
use crossroads_model::{NetworkSpec, Precision, QNetwork, absorbing_go_of, network_spec};
use tch::{Device, Kind, Tensor};

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
    /// Exact *go* labels weighed apart (`learner.go_label_weight`); `None`
    /// weighs every item by its importance alone.
    pub go_labels: Option<GoLabels>,
}

/// Items whose action is the absorbing *go* `action` and whose discount is
/// 0 (nothing bootstrapped: an exact label) have their importance weight
/// multiplied by `weight` in the loss; their priorities are unchanged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoLabels {
    /// The action set's absorbing *go*.
    pub action: usize,
    /// The multiplier.
    pub weight: f64,
}

impl GoLabels {
    /// From `learner.go_label_weight` and the action set; `None` at 1.
    /// An error for another weight where the set has no absorbing *go*
    /// (configuration validation says so first).
    fn from_config(action_set: &str, weight: f64) -> Result<Option<Self>, LearnerError> {
        if weight == 1.0 {
            return Ok(None);
        }
        let action = absorbing_go_of(action_set)
            .map_err(|e| LearnerError::Config(e.to_string()))?
            .ok_or_else(|| {
            LearnerError::Config(format!(
                "learner.go_label_weight is {weight}, and the {action_set} action set has no absorbing go to weigh"
            ))
        })?;
        Ok(Some(Self { action, weight }))
    }

    /// `weights` with this rule applied to `batch`'s exact *go* labels.
    fn apply(&self, weights: &Tensor, actions: &Tensor, discounts: &Tensor) -> Tensor {
        let exact = actions
            .eq(self.action as i64)
            .logical_and(&discounts.eq(0.0));
        let scale = exact.to_kind(weights.kind()) * (self.weight - 1.0) + 1.0;
        weights * scale
    }
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
            go_labels: GoLabels::from_config(&sim.action_set, c.go_label_weight)?,
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

/// An early phase of the run with its own learning rate and target
/// period (`learner.early_*`): the first `updates` updates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EarlyPhase {
    /// Updates it lasts.
    pub updates: u64,
    /// Its learning rate.
    pub learning_rate: f64,
    /// Its updates between hard target copies.
    pub target_period: u64,
}

impl EarlyPhase {
    /// The phase `[learner]` asks for; `None` without one (no
    /// `early_updates`, or neither early setting).
    pub fn from_config(c: &LearnerConfig) -> Option<Self> {
        let wanted = c.early_learning_rate.is_some() || c.early_target_period.is_some();
        (c.early_updates > 0 && wanted).then(|| Self {
            updates: c.early_updates,
            learning_rate: c.early_learning_rate.unwrap_or(c.learning_rate),
            target_period: c.early_target_period.unwrap_or(c.target_period),
        })
    }
}

/// The networks and optimizer of the learner. Owned by one thread.
#[derive(Debug)]
pub struct Trainer {
    config: TrainerConfig,
    early: Option<EarlyPhase>,
    online: QNetwork,
    target: QNetwork,
    optimizer: Optimizer,
    step: u64,
    device: Device,
}

impl Trainer {
    /// Fresh networks (the target a copy of the online one) and a zero
    /// optimizer state, on the CPU.
    pub fn new(config: TrainerConfig) -> Result<Self, LearnerError> {
        Self::new_on(config, Device::Cpu)
    }

    /// [`Trainer::new`] on `device` (what `runtime.device` resolves to,
    /// `crossroads_model::resolve_device`): both networks and the
    /// optimizer state there. The initial weights are the CPU's of the
    /// same seed. Off the CPU the optimizer runs its rule as tensor
    /// operations instead of the fused CPU pass ([`Optimizer::step`]).
    pub fn new_on(config: TrainerConfig, device: Device) -> Result<Self, LearnerError> {
        let online = QNetwork::new_on(config.spec.clone(), config.seed, device)?;
        let mut target = QNetwork::new_on(config.spec.clone(), config.seed, device)?;
        target.copy_from(&online)?;
        let optimizer = Optimizer::new(config.optimizer, online.parameters());
        Ok(Self {
            config,
            online,
            target,
            optimizer,
            step: 0,
            device,
            early: None,
        })
    }

    /// Gives the first `phase.updates` updates the phase's learning rate
    /// and target period; the configured ones hold after (counted from
    /// the trainer's step, so a restored trainer is in the right phase).
    pub fn set_early_phase(&mut self, phase: Option<EarlyPhase>) {
        self.early = phase;
    }

    /// The learning rate and target period of the next update.
    fn phase_settings(&self) -> (f64, u64) {
        match self.early {
            Some(e) if self.step < e.updates => (e.learning_rate, e.target_period),
            _ => (
                self.config.optimizer.learning_rate(),
                self.config.target_period,
            ),
        }
    }

    /// Where the networks and the optimizer state are.
    pub fn device(&self) -> Device {
        self.device
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
    /// online and target weights, optimizer state and the update count,
    /// onto this trainer's device. Checks everything before changing
    /// anything.
    pub fn restore(&mut self, state: TrainerState) -> Result<(), LearnerError> {
        let precision = self.online.precision();
        let mut online = QNetwork::new_on(self.config.spec.clone(), 0, self.device)?;
        online.load_safetensors(&state.online)?;
        online.set_precision(precision);
        let mut target = QNetwork::new_on(self.config.spec.clone(), 0, self.device)?;
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

    /// One update on `batch`, stage by stage. A batch on the CPU is moved
    /// to the trainer's device first, when that is another.
    pub fn update(&mut self, batch: &TrainingBatch) -> Result<UpdateStats, LearnerError> {
        if self.device == Device::Cpu {
            self.update_here(batch)
        } else {
            let moved = batch.to_device(self.device);
            self.update_here(&moved)
        }
    }

    /// [`Trainer::update`] of a batch on the trainer's device. The
    /// priorities and statistics are read back to the CPU.
    fn update_here(&mut self, batch: &TrainingBatch) -> Result<UpdateStats, LearnerError> {
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

        // Loss: Huber on the TD errors, weighted by importance (and exact
        // go labels by `learner.go_label_weight`).
        let q_sa = taken(&self.online.q_values_of(&batch.obs)?, &batch.actions);
        let loss = match c.go_labels {
            None => weighted_huber(&q_sa, &targets, &batch.weights, c.huber_delta),
            Some(go) => {
                let weights = go.apply(&batch.weights, &batch.actions, &batch.discounts);
                weighted_huber(&q_sa, &targets, &weights, c.huber_delta)
            }
        };
        let loss_value = loss.double_value(&[]);
        if !loss_value.is_finite() {
            return Err(LearnerError::Diverged {
                step: self.step + 1,
                loss: loss_value,
            });
        }

        // Optimizer step, the gradient clipped by its global norm.
        let (learning_rate, target_period) = self.phase_settings();
        self.optimizer.set_learning_rate(learning_rate);
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
                if self.step.is_multiple_of(target_period) {
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

    /// The training state as a checkpoint stores it, on the CPU whatever
    /// the trainer's device.
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
