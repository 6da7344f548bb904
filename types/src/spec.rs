//! What a Q-network is: the observation it reads, the actions it scores and
//! the shape of its trunk. A [`NetworkSpec`] travels with every copy of the
//! weights, so weights are only ever applied to a network they fit.
//!
//! [`ObservationLayout::named`] knows the simulator's four views
//! ([`ObservationLayout::KINDS`]). Neither this crate nor
//! `crossroads_model` depends on the simulator, so a root test
//! (`tests/it/learner.rs`) checks that the layouts match what
//! `crossroads_sim` writes. Errors are a [`SpecError`].

use serde::{Deserialize, Serialize};

use crate::batch::MAX_OBSERVATION_LEN;

/// Why a network spec, or the metadata of a weights file, is not valid.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SpecError {
    /// A dimension, observation kind, action set or trunk is invalid.
    #[error("invalid network spec: {0}")]
    Invalid(String),
    /// The metadata is not that of a weights file of this format.
    #[error("invalid weights file: {0}")]
    Format(String),
}

/// Dense features after the grid in every simulator observation (the ego's
/// own state; `crossroads_sim::EGO_FEATURES`).
pub const EGO_FEATURES: i64 = 4;

/// How a flat observation is laid out: a channel-major grid
/// `[channels][rows][cols]` followed by `extra` dense features, as the
/// simulator writes it.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationLayout {
    /// Simulator view: `ttg`, `ttg-occlusion`, `sequential` or
    /// `sequential-occlusion`.
    pub kind: String,
    /// Grid channels.
    pub channels: i64,
    /// Grid rows.
    pub rows: i64,
    /// Grid columns.
    pub cols: i64,
    /// Dense features after the grid.
    pub extra: i64,
}

impl ObservationLayout {
    /// The names [`ObservationLayout::named`] knows.
    pub const KINDS: [&'static str; 4] =
        ["ttg", "ttg-occlusion", "sequential", "sequential-occlusion"];

    /// The layout of a simulator view: the TTG grid is 5 x 18 x 26
    /// (occupied, heading, speed, x and y offset in the cell), the
    /// Sequential grid 6 x 5 x 11 (plus time to collision); `-occlusion`
    /// adds an occluded channel. Each is followed by [`EGO_FEATURES`]
    /// values.
    pub fn named(kind: &str) -> Result<Self, SpecError> {
        let (channels, rows, cols) = match kind {
            "ttg" => (5, 18, 26),
            "ttg-occlusion" => (6, 18, 26),
            "sequential" => (6, 5, 11),
            "sequential-occlusion" => (7, 5, 11),
            other => {
                return Err(SpecError::Invalid(format!(
                    "unknown observation kind {other:?}; expected one of {}",
                    Self::KINDS.join(", ")
                )));
            }
        };
        Ok(Self {
            kind: kind.to_owned(),
            channels,
            rows,
            cols,
            extra: EGO_FEATURES,
        })
    }

    /// Values in the grid part.
    pub fn grid_len(&self) -> i64 {
        self.channels * self.rows * self.cols
    }

    /// Values in one flat observation.
    pub fn len(&self) -> i64 {
        self.grid_len() + self.extra
    }

    /// Whether an observation has no values (never for a valid layout).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The action sets the simulator knows (`crossroads_sim::ActionSet`).
pub const ACTION_SETS: [&str; 3] = ["ttg", "sequential", "creep"];

/// Number of actions of an action set: `ttg` 5, `sequential` 12, `creep` 3.
pub fn num_actions_of(action_set: &str) -> Result<i64, SpecError> {
    match action_set {
        "ttg" => Ok(5),
        "sequential" => Ok(12),
        "creep" => Ok(3),
        other => Err(SpecError::Invalid(format!(
            "unknown action set {other:?}; expected one of {}",
            ACTION_SETS.join(", ")
        ))),
    }
}

/// The trunk between the observation and the dueling heads.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum TrunkKind {
    /// Fully connected layers over the flat observation, ReLU after each.
    #[default]
    Mlp,
    /// 3x3 convolutions over the grid (the first with stride 1, the others
    /// stride 2, ReLU after each), flattened, joined with the dense
    /// features, then one fully connected layer.
    Conv,
}

impl TrunkKind {
    /// Lower-case name, as on the wire.
    pub fn name(self) -> &'static str {
        match self {
            TrunkKind::Mlp => "mlp",
            TrunkKind::Conv => "conv",
        }
    }

    /// Parses `mlp` or `conv`.
    pub fn parse(s: &str) -> Result<Self, SpecError> {
        match s {
            "mlp" => Ok(TrunkKind::Mlp),
            "conv" => Ok(TrunkKind::Conv),
            other => Err(SpecError::Invalid(format!(
                "unknown trunk {other:?}; expected mlp or conv"
            ))),
        }
    }
}

/// Everything that fixes a network's tensors.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkSpec {
    /// What the network reads.
    pub observation: ObservationLayout,
    /// Action set name: `ttg`, `sequential` or `creep`.
    pub action_set: String,
    /// Outputs, one Q-value per action.
    pub num_actions: i64,
    /// Trunk kind.
    pub trunk: TrunkKind,
    /// For `mlp`, the widths of the hidden layers. For `conv`, the channels
    /// of each convolution followed by the width of the fully connected
    /// layer (so at least two entries).
    pub hidden: Vec<i64>,
}

impl NetworkSpec {
    /// The spec for a simulator view and action set, checked.
    pub fn new(
        observation: &str,
        action_set: &str,
        trunk: TrunkKind,
        hidden: Vec<i64>,
    ) -> Result<Self, SpecError> {
        let spec = Self {
            observation: ObservationLayout::named(observation)?,
            action_set: action_set.to_owned(),
            num_actions: num_actions_of(action_set)?,
            trunk,
            hidden,
        };
        spec.validate()?;
        Ok(spec)
    }

    /// Checks that every dimension is positive and fits the trunk, and
    /// that an observation has at most [`MAX_OBSERVATION_LEN`] values (so
    /// [`input_len`](Self::input_len) cannot overflow).
    pub fn validate(&self) -> Result<(), SpecError> {
        let o = &self.observation;
        if o.channels <= 0 || o.rows <= 0 || o.cols <= 0 || o.extra < 0 {
            return Err(SpecError::Invalid(format!(
                "observation dimensions must be positive: {o:?}"
            )));
        }
        let len = o
            .channels
            .checked_mul(o.rows)
            .and_then(|grid| grid.checked_mul(o.cols))
            .and_then(|grid| grid.checked_add(o.extra));
        if len.is_none_or(|len| len > MAX_OBSERVATION_LEN as i64) {
            return Err(SpecError::Invalid(format!(
                "an observation must have at most {MAX_OBSERVATION_LEN} values: {o:?}"
            )));
        }
        if self.num_actions <= 0 {
            return Err(SpecError::Invalid(format!(
                "num_actions must be positive, got {}",
                self.num_actions
            )));
        }
        if let Some(h) = self.hidden.iter().find(|&&h| h <= 0 || h > 1 << 16) {
            return Err(SpecError::Invalid(format!(
                "hidden sizes must be between 1 and 65536, got {h} in {:?}",
                self.hidden
            )));
        }
        if self.trunk == TrunkKind::Conv && self.hidden.len() < 2 {
            return Err(SpecError::Invalid(format!(
                "a conv trunk needs at least one convolution's channels and the fully connected width, got {:?}",
                self.hidden
            )));
        }
        Ok(())
    }

    /// Input values the network expects per observation.
    pub fn input_len(&self) -> i64 {
        self.observation.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `[channels, rows, cols]` come from the wire as u32, and their
    /// product overflowed i64 in `input_len` after `validate` had accepted
    /// them (the `wire_weights` fuzz target asserts that a valid spec has
    /// a length).
    #[test]
    fn an_observation_too_large_to_count_is_invalid() {
        let mut spec = NetworkSpec::new("ttg", "ttg", TrunkKind::Mlp, vec![8]).expect("spec");
        spec.observation.channels = i64::from(u32::MAX);
        spec.observation.rows = i64::from(u32::MAX);
        spec.observation.cols = i64::from(u32::MAX);
        let err = spec.validate().expect_err("2^96 values");
        assert!(err.to_string().contains("at most"), "{err}");
        spec.observation.channels = 1 << 12;
        spec.observation.rows = 1 << 12;
        spec.observation.cols = 1;
        spec.observation.extra = 1;
        assert!(spec.validate().is_err(), "one value above the limit");
        spec.observation.extra = 0;
        assert_eq!(spec.validate(), Ok(()));
        assert_eq!(spec.input_len(), 1 << 24);
    }
}
