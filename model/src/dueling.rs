//! The dueling architecture over an MLP trunk.

use tch::{Tensor, nn};

use crate::ModelError;

/// Shape of a [`DuelingMlp`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MlpSpec {
    /// Length of a flattened observation.
    pub input: i64,
    /// Widths of the trunk's hidden layers (ReLU after each).
    pub hidden: Vec<i64>,
    /// Number of discrete actions.
    pub num_actions: i64,
}

/// A dueling Q-network: trunk, then value and advantage heads.
#[derive(Debug)]
pub struct DuelingMlp {
    spec: MlpSpec,
    trunk: Vec<nn::Linear>,
    value: nn::Linear,
    advantage: nn::Linear,
}

impl DuelingMlp {
    /// Creates the layers under `path` (variables `trunk.<i>`, `value`,
    /// `advantage`, each with `weight` and `bias`).
    pub fn new(path: &nn::Path<'_>, spec: MlpSpec) -> Result<Self, ModelError> {
        if spec.input <= 0 || spec.num_actions <= 0 || spec.hidden.iter().any(|&h| h <= 0) {
            return Err(ModelError::Spec(format!(
                "every dimension must be positive: {spec:?}"
            )));
        }
        let mut trunk = Vec::with_capacity(spec.hidden.len());
        let mut width = spec.input;
        for (i, &h) in spec.hidden.iter().enumerate() {
            trunk.push(nn::linear(path / "trunk" / i, width, h, Default::default()));
            width = h;
        }
        let value = nn::linear(path / "value", width, 1, Default::default());
        let advantage = nn::linear(
            path / "advantage",
            width,
            spec.num_actions,
            Default::default(),
        );
        Ok(Self {
            spec,
            trunk,
            value,
            advantage,
        })
    }

    /// The network's shape.
    pub fn spec(&self) -> &MlpSpec {
        &self.spec
    }

    /// Q-values, shape `[batch, num_actions]`, for observations of shape
    /// `[batch, input]`.
    pub fn q_values(&self, obs: &Tensor) -> Result<Tensor, ModelError> {
        let size = obs.size();
        if size.len() != 2 || size[1] != self.spec.input {
            return Err(ModelError::Shape {
                expected: self.spec.input,
                got: size,
            });
        }
        let mut h = obs.shallow_clone();
        for layer in &self.trunk {
            h = h.apply(layer).relu();
        }
        let value = h.apply(&self.value);
        let advantage = h.apply(&self.advantage);
        let mean = advantage.mean_dim(1, true, tch::Kind::Float);
        Ok(value + advantage - mean)
    }
}
