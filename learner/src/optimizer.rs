//! RMSProp and Adam over tch tensors, written out so that their state can
//! be saved and restored exactly (tch's optimizers do not expose it).
//!
//! The update rules are PyTorch's (`torch.optim.RMSprop` uncentered without
//! momentum, `torch.optim.Adam` without weight decay), so the PyTorch
//! benchmark runs the same arithmetic. State tensors are named after
//! PyTorch's state keys: `square_avg.<variable>` for RMSProp,
//! `exp_avg.<variable>` and `exp_avg_sq.<variable>` for Adam.
//!
//! On the CPU a step is one fused pass over each parameter's memory
//! (`fused`); with parameters elsewhere (a CUDA learner) it is the same
//! rule, with the same constants, as tensor operations where the
//! parameters are. The state is the same in both, and [`Optimizer::state`]
//! returns it on the CPU.

use std::collections::HashMap;

use crossroads_config::{LearnerConfig, OptimizerKind};
use crossroads_model::ModelError;
use tch::{Device, Kind, Tensor};

mod fused;

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
    /// Its step size.
    pub fn learning_rate(&self) -> f64 {
        match *self {
            Self::Rmsprop { lr, .. } | Self::Adam { lr, .. } => lr,
        }
    }

    /// The same optimizer with step size `learning_rate`.
    pub fn with_learning_rate(mut self, learning_rate: f64) -> Self {
        match &mut self {
            Self::Rmsprop { lr, .. } | Self::Adam { lr, .. } => *lr = learning_rate,
        }
        self
    }

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
    /// Every parameter is on the CPU: steps take the fused pass.
    fused: bool,
}

impl std::fmt::Debug for Optimizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Optimizer")
            .field("config", &self.config)
            .field("params", &self.params.len())
            .field("steps", &self.steps)
            .field("fused", &self.fused)
            .finish()
    }
}

/// The factor that scales a gradient of global norm `total` down to
/// `max_norm` (1 when it is within it or clipping is off).
fn clip_scale(total: f64, max_norm: f64) -> f32 {
    if max_norm > 0.0 && total > max_norm {
        (max_norm / (total + 1e-6)) as f32
    } else {
        1.0
    }
}

impl Optimizer {
    /// An optimizer of `params` (name, variable; the variables are updated
    /// in place), with zero state on the parameters' device. Parameters
    /// all on the CPU take the fused step; any elsewhere, the step as
    /// tensor operations.
    pub fn new(config: OptimizerConfig, params: Vec<(String, Tensor)>) -> Self {
        let fused = params.iter().all(|(_, p)| p.device() == Device::Cpu);
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
            fused,
        }
    }

    /// This optimizer taking its step as tensor operations even where the
    /// fused CPU pass applies: what a learner off the CPU runs, so that
    /// the two can be compared on any machine.
    pub fn unfused(mut self) -> Self {
        self.fused = false;
        self
    }

    /// Whether steps take the fused CPU pass (every parameter on the CPU,
    /// and not [`Optimizer::unfused`]).
    pub fn is_fused(&self) -> bool {
        self.fused
    }

    /// Sets the step size of the steps to come (the state is kept).
    pub fn set_learning_rate(&mut self, learning_rate: f64) {
        self.config = self.config.with_learning_rate(learning_rate);
    }

    /// The hyperparameters.
    pub fn config(&self) -> OptimizerConfig {
        self.config
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The parameters, in the order [`Optimizer::gradients`] returns
    /// their gradients.
    pub fn parameters(&self) -> Vec<&Tensor> {
        self.params.iter().map(|p| &p.value).collect()
    }

    /// The gradient of `loss` with respect to each parameter, as fresh
    /// tensors: nothing is accumulated into (or has to be cleared from)
    /// the variables' `.grad`. A parameter `loss` does not depend on gets
    /// a zero gradient.
    pub fn gradients(&self, loss: &Tensor) -> Result<Vec<Tensor>, ModelError> {
        let params = self.parameters();
        let grads = Tensor::f_run_backward(&[loss], &params, false, false)?;
        Ok(grads
            .into_iter()
            .zip(params)
            .map(|(g, p)| if g.defined() { g } else { p.zeros_like() })
            .collect())
    }

    /// One update from `grads` (one per parameter, as
    /// [`Optimizer::gradients`] gives them): their global L2 norm, and when
    /// `max_norm` is above 0 and the norm exceeds it, the gradients scaled
    /// down to it; then each parameter and its state in one pass over
    /// memory. Returns the norm before clipping.
    ///
    /// The arithmetic is PyTorch's (in f32); on the CPU the pass is fused
    /// because the same rule as separate tensor operations reads and
    /// writes every parameter a dozen times, a third of a whole update of
    /// the MLP. Off the CPU it is those tensor operations, on the
    /// parameters' device.
    pub fn step(&mut self, grads: &[Tensor], max_norm: f64) -> Result<f64, ModelError> {
        if grads.len() != self.params.len() {
            return Err(ModelError::Format(format!(
                "{} gradients for {} parameters",
                grads.len(),
                self.params.len()
            )));
        }
        let grads: Vec<Tensor> = grads.iter().map(Tensor::contiguous).collect();
        for (p, g) in self.params.iter().zip(&grads) {
            if g.size() != p.value.size() || g.kind() != Kind::Float {
                return Err(ModelError::Format(format!(
                    "gradient of {} is {:?} {:?}; the parameter is {:?} f32",
                    p.name,
                    g.kind(),
                    g.size(),
                    p.value.size()
                )));
            }
        }
        if !self.fused {
            return Ok(self.step_tensors(&grads, max_norm));
        }
        let total = grads
            .iter()
            .map(|g| fused::with_slices(g, &mut [], |g, _| fused::sum_of_squares(g)))
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(|| ModelError::Format("a gradient is not a dense CPU tensor".to_owned()))?
            .iter()
            .sum::<f64>()
            .sqrt();
        let scale = clip_scale(total, max_norm);
        self.steps += 1;
        let rule = fused::Rule::new(self.config, self.steps);
        for (p, g) in self.params.iter_mut().zip(&grads) {
            let mut state: Vec<&mut Tensor> = std::iter::once(&mut p.value)
                .chain(p.slots.iter_mut())
                .collect();
            fused::with_slices(g, &mut state, |g, state| rule.apply(g, scale, state)).ok_or_else(
                || {
                    ModelError::Format(format!(
                        "parameter {} is not a dense CPU f32 tensor",
                        p.name
                    ))
                },
            )?;
        }
        Ok(total)
    }

    /// [`Optimizer::step`] with the parameters off the CPU: the global
    /// norm (summed in f64) and the rule of [`fused::Rule`], with its
    /// constants, as tensor operations on the parameters' device. Returns
    /// the norm before clipping. `grads` are checked already.
    fn step_tensors(&mut self, grads: &[Tensor], max_norm: f64) -> f64 {
        let total = if grads.is_empty() {
            0.0
        } else {
            let squares: Vec<Tensor> = grads.iter().map(|g| g.square().sum(Kind::Double)).collect();
            Tensor::stack(&squares, 0)
                .sum(Kind::Double)
                .double_value(&[])
                .sqrt()
        };
        let scale = clip_scale(total, max_norm);
        self.steps += 1;
        let rule = fused::Rule::new(self.config, self.steps);
        tch::no_grad(|| {
            for (p, g) in self.params.iter_mut().zip(grads) {
                let g = g * f64::from(scale);
                match (rule, p.slots.as_mut_slice()) {
                    (fused::Rule::Rmsprop { lr, decay, eps }, [sq]) => {
                        // v += (1 - decay)(g^2 - v); p -= lr g / (sqrt(v) + eps)
                        let dv = (g.square() - &*sq) * f64::from(1.0 - decay);
                        *sq += dv;
                        let dp = &g * f64::from(lr) / (sq.sqrt() + f64::from(eps));
                        p.value -= dp;
                    }
                    (
                        fused::Rule::Adam {
                            step_size,
                            beta1,
                            beta2,
                            root_correction,
                            eps,
                        },
                        [m, v],
                    ) => {
                        // m += (1 - b1)(g - m); v += (1 - b2)(g^2 - v);
                        // p -= step_size m / (sqrt(v) root_correction + eps)
                        let dm = (&g - &*m) * f64::from(1.0 - beta1);
                        *m += dm;
                        let dv = (g.square() - &*v) * f64::from(1.0 - beta2);
                        *v += dv;
                        let denominator = v.sqrt() * f64::from(root_correction) + f64::from(eps);
                        let dp = &*m * f64::from(step_size) / denominator;
                        p.value -= dp;
                    }
                    (rule, slots) => {
                        debug_assert!(false, "{rule:?} with {} state slots", slots.len());
                    }
                }
            }
        });
        total
    }

    /// The state as named tensors (copies, on the CPU) and the step count.
    pub fn state(&self) -> (Vec<(String, Tensor)>, u64) {
        let names = self.config.slot_names();
        let mut out = Vec::new();
        for p in &self.params {
            for (slot, t) in names.iter().zip(&p.slots) {
                let t = if t.device() == Device::Cpu {
                    t.detach().copy()
                } else {
                    t.detach().to_device(Device::Cpu)
                };
                out.push((format!("{slot}.{}", p.name), t));
            }
        }
        (out, self.steps)
    }

    /// Restores state written by [`Optimizer::state`]: every slot of every
    /// parameter once, with its shape and finite values, copied onto the
    /// parameters' device. All or nothing.
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
