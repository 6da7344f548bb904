//! RMSProp and Adam over tch tensors, written out so that their state can
//! be saved and restored exactly (tch's optimizers do not expose it).
//!
//! The update rules are PyTorch's (`torch.optim.RMSprop` uncentered without
//! momentum, `torch.optim.Adam` without weight decay), so the PyTorch
//! benchmark runs the same arithmetic. State tensors are named after
//! PyTorch's state keys: `square_avg.<variable>` for RMSProp,
//! `exp_avg.<variable>` and `exp_avg_sq.<variable>` for Adam.

use std::collections::HashMap;

use crossroads_config::{LearnerConfig, OptimizerKind};
use crossroads_model::ModelError;
use tch::Tensor;

/// Hyperparameters of the optimizer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OptimizerConfig {
    /// `v = decay v + (1 - decay) g^2; p -= lr g / (sqrt(v) + eps)`.
    Rmsprop {
        /// Step size.
        lr: f64,
        /// Decay of the squared-gradient average.
        decay: f64,
        /// Added to the root.
        eps: f64,
    },
    /// Adam with bias correction.
    Adam {
        /// Step size.
        lr: f64,
        /// First-moment decay.
        beta1: f64,
        /// Second-moment decay.
        beta2: f64,
        /// Added to the root.
        eps: f64,
    },
}

impl OptimizerConfig {
    /// The optimizer `config` asks for.
    pub fn from_config(config: &LearnerConfig) -> Self {
        match config.optimizer {
            OptimizerKind::Rmsprop => OptimizerConfig::Rmsprop {
                lr: config.learning_rate,
                decay: config.rmsprop_decay,
                eps: config.rmsprop_eps,
            },
            OptimizerKind::Adam => OptimizerConfig::Adam {
                lr: config.learning_rate,
                beta1: config.adam_beta1,
                beta2: config.adam_beta2,
                eps: config.adam_eps,
            },
        }
    }

    /// `rmsprop` or `adam`.
    pub fn name(&self) -> &'static str {
        match self {
            OptimizerConfig::Rmsprop { .. } => "rmsprop",
            OptimizerConfig::Adam { .. } => "adam",
        }
    }

    fn slot_names(&self) -> &'static [&'static str] {
        match self {
            OptimizerConfig::Rmsprop { .. } => &["square_avg"],
            OptimizerConfig::Adam { .. } => &["exp_avg", "exp_avg_sq"],
        }
    }
}

struct Param {
    name: String,
    value: Tensor,
    slots: Vec<Tensor>,
}

/// An optimizer over named parameters. Not thread-safe; the training loop
/// owns it.
pub struct Optimizer {
    config: OptimizerConfig,
    params: Vec<Param>,
    steps: u64,
}

impl std::fmt::Debug for Optimizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Optimizer")
            .field("config", &self.config)
            .field("params", &self.params.len())
            .field("steps", &self.steps)
            .finish()
    }
}

impl Optimizer {
    /// An optimizer of `params` (name, variable; the variables are updated
    /// in place), with zero state.
    pub fn new(config: OptimizerConfig, params: Vec<(String, Tensor)>) -> Self {
        let slots = config.slot_names().len();
        let params = params
            .into_iter()
            .map(|(name, value)| {
                let state = (0..slots).map(|_| value.zeros_like()).collect();
                Param {
                    name,
                    value,
                    slots: state,
                }
            })
            .collect();
        Self {
            config,
            params,
            steps: 0,
        }
    }

    /// The hyperparameters.
    pub fn config(&self) -> OptimizerConfig {
        self.config
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Clears every parameter's gradient.
    pub fn zero_grad(&mut self) {
        for p in &mut self.params {
            p.value.zero_grad();
        }
    }

    /// The global L2 norm of the gradients; when `max_norm` is above 0 and
    /// the norm exceeds it, scales every gradient down to it. Returns the
    /// norm before clipping.
    pub fn clip_grad_norm(&mut self, max_norm: f64) -> f64 {
        let grads: Vec<Tensor> = self
            .params
            .iter()
            .map(|p| p.value.grad())
            .filter(Tensor::defined)
            .collect();
        if grads.is_empty() {
            return 0.0;
        }
        let norms: Vec<Tensor> = grads.iter().map(|g| g.norm()).collect();
        let total = Tensor::stack(&norms, 0).norm().double_value(&[]);
        if max_norm > 0.0 && total > max_norm {
            let scale = max_norm / (total + 1e-6);
            tch::no_grad(|| {
                for mut g in grads {
                    let _ = g.g_mul_scalar_(scale);
                }
            });
        }
        total
    }

    /// Applies one update from the current gradients.
    pub fn step(&mut self) {
        self.steps += 1;
        let t = self.steps as i32;
        let config = self.config;
        tch::no_grad(|| {
            for p in &mut self.params {
                let g = p.value.grad();
                if !g.defined() {
                    continue;
                }
                match config {
                    // In place where tch allows, and few passes over each
                    // tensor: v += (1 - decay)(g^2 - v) is decay v +
                    // (1 - decay) g^2, and -lr folds into the denominator.
                    OptimizerConfig::Rmsprop { lr, decay, eps } => {
                        let sq = &mut p.slots[0];
                        let _ = sq.lerp_(&g.square(), 1.0 - decay);
                        let mut denom = sq.sqrt();
                        let _ = denom.g_add_scalar_(eps);
                        let _ = denom.g_mul_scalar_(-1.0 / lr);
                        let _ = p.value.addcdiv_(&g, &denom);
                    }
                    OptimizerConfig::Adam {
                        lr,
                        beta1,
                        beta2,
                        eps,
                    } => {
                        let (m, v) = p.slots.split_at_mut(1);
                        let (m, v) = (&mut m[0], &mut v[0]);
                        let _ = m.lerp_(&g, 1.0 - beta1);
                        let _ = v.lerp_(&g.square(), 1.0 - beta2);
                        let bias1 = 1.0 - beta1.powi(t);
                        let bias2 = 1.0 - beta2.powi(t);
                        // p -= lr / bias1 * m / (sqrt(v / bias2) + eps)
                        let mut denom = v.sqrt();
                        let _ = denom.g_mul_scalar_(1.0 / bias2.sqrt());
                        let _ = denom.g_add_scalar_(eps);
                        let _ = denom.g_mul_scalar_(-bias1 / lr);
                        let _ = p.value.addcdiv_(m, &denom);
                    }
                }
            }
        });
    }

    /// The state as named tensors (copies) and the step count.
    pub fn state(&self) -> (Vec<(String, Tensor)>, u64) {
        let names = self.config.slot_names();
        let mut out = Vec::new();
        for p in &self.params {
            for (slot, t) in names.iter().zip(&p.slots) {
                out.push((format!("{slot}.{}", p.name), t.detach().copy()));
            }
        }
        (out, self.steps)
    }

    /// Restores state written by [`Optimizer::state`]: every slot of every
    /// parameter once, with its shape and finite values. All or nothing.
    pub fn load_state(
        &mut self,
        tensors: Vec<(String, Tensor)>,
        steps: u64,
    ) -> Result<(), ModelError> {
        let names = self.config.slot_names();
        let mut slots: HashMap<String, Tensor> = HashMap::new();
        for p in &self.params {
            for (slot, t) in names.iter().zip(&p.slots) {
                slots.insert(format!("{slot}.{}", p.name), t.shallow_clone());
            }
        }
        crossroads_model::weights::assign(&slots, tensors).map_err(|e| {
            ModelError::Format(format!(
                "optimizer state does not fit this {} optimizer: {e}",
                self.config.name()
            ))
        })?;
        self.steps = steps;
        Ok(())
    }
}
