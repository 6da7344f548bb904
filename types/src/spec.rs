//! What a Q-network is: the observation it reads, the actions it scores and
//! the shape of its trunk. A [`NetworkSpec`] travels with every copy of the
//! weights, so weights are only ever applied to a network they fit.
//!
//! An [`ObservationLayout`] is plain data here: the simulator owns the
//! views and their sizes (`crossroads_sim::observation_layout`), batches and
//! networks carry the layout they were made for, and receivers compare
//! layouts instead of keeping a copy of the sizes. Errors are a
//! [`SpecError`].

use std::fmt;

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

/// How a flat observation is laid out: a channel-major grid
/// `[channels][rows][cols]` followed by `extra` dense features, as the
/// simulator writes it (`crossroads_sim::ObsSpec::layout`). Weights files
/// store it as JSON, so the field names are part of their format.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationLayout {
    /// Simulator view, e.g. `ttg` (`crossroads_sim::OBSERVATION_KINDS`).
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
    /// A layout of `kind`: a `channels x rows x cols` grid, then `extra`
    /// dense values. Not checked here; see [`check`](Self::check).
    pub fn new(kind: impl Into<String>, channels: i64, rows: i64, cols: i64, extra: i64) -> Self {
        Self {
            kind: kind.into(),
            channels,
            rows,
            cols,
            extra,
        }
    }

    /// What a replay file of an earlier build stood for: it kept only the
    /// kind and the flat length, read as a `1 x 1 x len` grid (see
    /// [`reads_as`](Self::reads_as)).
    pub fn legacy(kind: impl Into<String>, len: i64) -> Self {
        Self::new(kind, 1, 1, len, 0)
    }

    /// Whether this is a flat `1 x 1 x len` layout without extra values, as
    /// [`legacy`](Self::legacy) makes.
    pub fn is_legacy(&self) -> bool {
        self.channels == 1 && self.rows == 1 && self.extra == 0
    }

    /// Whether observations stored under `self` read as observations of
    /// `other`: the same layout, or `self` a legacy one
    /// ([`legacy`](Self::legacy)) of the same kind and length.
    pub fn reads_as(&self, other: &Self) -> bool {
        self == other
            || (self.is_legacy()
                && self.kind == other.kind
                && self.check().is_ok_and(|len| other.check() == Ok(len)))
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

    /// Checks that the kind is named, every grid dimension is positive,
    /// `extra` is not negative and an observation has at most
    /// [`MAX_OBSERVATION_LEN`] values (so [`len`](Self::len) cannot
    /// overflow); returns that length.
    pub fn check(&self) -> Result<usize, String> {
        if self.kind.is_empty() {
            return Err(format!("the observation kind must not be empty: {self}"));
        }
        if self.channels <= 0 || self.rows <= 0 || self.cols <= 0 || self.extra < 0 {
            return Err(format!("observation dimensions must be positive: {self}"));
        }
        self.channels
            .checked_mul(self.rows)
            .and_then(|grid| grid.checked_mul(self.cols))
            .and_then(|grid| grid.checked_add(self.extra))
            .and_then(|len| usize::try_from(len).ok())
            .filter(|len| *len <= MAX_OBSERVATION_LEN)
            .ok_or_else(|| {
                format!("an observation must have at most {MAX_OBSERVATION_LEN} values: {self}")
            })
    }
}

/// `kind [channels x rows x cols + extra]`, e.g. `ttg [5x18x26 + 4]`.
impl fmt::Display for ObservationLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} [{}x{}x{} + {}]",
            self.kind, self.channels, self.rows, self.cols, self.extra
        )
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

/// The index of an action set's absorbing *go* (the one action that ends
/// the episode, `ttg` 0, `creep` 2), `None` for `sequential`.
pub fn absorbing_go_of(action_set: &str) -> Result<Option<usize>, SpecError> {
    num_actions_of(action_set)?;
    Ok(match action_set {
        "ttg" => Some(0),
        "creep" => Some(2),
        _ => None,
    })
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
    /// The spec for an observation layout and action set, checked.
    pub fn new(
        observation: ObservationLayout,
        action_set: &str,
        trunk: TrunkKind,
        hidden: Vec<i64>,
    ) -> Result<Self, SpecError> {
        let spec = Self {
            observation,
            action_set: action_set.to_owned(),
            num_actions: num_actions_of(action_set)?,
            trunk,
            hidden,
        };
        spec.validate()?;
        Ok(spec)
    }

    /// Checks the observation layout ([`ObservationLayout::check`]: at most
    /// [`MAX_OBSERVATION_LEN`] values, so [`input_len`](Self::input_len)
    /// cannot overflow) and that every other dimension is positive and fits
    /// the trunk.
    pub fn validate(&self) -> Result<(), SpecError> {
        self.observation.check().map_err(SpecError::Invalid)?;
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

    /// A small valid layout.
    fn toy() -> ObservationLayout {
        ObservationLayout::new("toy", 2, 3, 4, 1)
    }

    /// `[channels, rows, cols]` come from the wire as u32, and their
    /// product overflowed i64 in `input_len` after `validate` had accepted
    /// them (the `wire_weights` fuzz target asserts that a valid spec has
    /// a length).
    #[test]
    fn an_observation_too_large_to_count_is_invalid() {
        let mut spec = NetworkSpec::new(toy(), "ttg", TrunkKind::Mlp, vec![8]).expect("spec");
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

    #[test]
    fn a_layout_is_checked_and_shown() {
        assert_eq!(toy().check(), Ok(25));
        assert_eq!(toy().to_string(), "toy [2x3x4 + 1]");
        for bad in [
            ObservationLayout::new("", 2, 3, 4, 1),
            ObservationLayout::new("toy", 0, 3, 4, 1),
            ObservationLayout::new("toy", 2, -3, 4, 1),
            ObservationLayout::new("toy", 2, 3, 4, -1),
        ] {
            assert!(bad.check().is_err(), "{bad}");
            let err = NetworkSpec::new(bad, "ttg", TrunkKind::Mlp, vec![8]).expect_err("invalid");
            assert!(err.to_string().contains("observation"), "{err}");
        }
    }

    /// Replay files of earlier builds kept only the kind and the flat
    /// length; such a layout reads as any layout of that kind and length.
    #[test]
    fn a_legacy_layout_reads_as_one_of_its_kind_and_length() {
        let legacy = ObservationLayout::legacy("toy", 25);
        assert!(legacy.is_legacy() && !toy().is_legacy());
        assert!(legacy.reads_as(&toy()));
        assert!(toy().reads_as(&toy()));
        assert!(
            !toy().reads_as(&legacy),
            "only the stored side may be legacy"
        );
        assert!(!ObservationLayout::legacy("toy", 24).reads_as(&toy()));
        assert!(!ObservationLayout::legacy("other", 25).reads_as(&toy()));
    }
}
