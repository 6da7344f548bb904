//! The error type of the crate.

/// Everything that can go wrong when loading scenarios, parsing policies or
/// running evaluations.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// No built-in scenario has this name.
    #[error("unknown scenario {name:?}; built-in scenarios: {known}")]
    UnknownScenario {
        /// The name asked for.
        name: String,
        /// The names that exist, comma separated.
        known: String,
    },
    /// No observation view has this name.
    #[error("unknown observation {name:?}; expected one of {known}")]
    UnknownObservation {
        /// The name asked for.
        name: String,
        /// The names that exist, comma separated.
        known: String,
    },
    /// A scenario file could not be read.
    #[error("cannot read scenario file {path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A scenario description is not valid TOML for the schema.
    #[error("scenario {what}: {source}")]
    Parse {
        /// Which scenario.
        what: String,
        /// The parser's message.
        source: Box<toml::de::Error>,
    },
    /// A scenario description parses but makes no sense.
    #[error("scenario {what}: {problem}")]
    Invalid {
        /// Which scenario or part of it.
        what: String,
        /// What is wrong.
        problem: String,
    },
    /// A policy string could not be parsed.
    #[error("invalid policy {spec:?}: {problem}")]
    PolicySpec {
        /// The string given.
        spec: String,
        /// What is wrong.
        problem: String,
    },
    /// The shield's assumptions (`--shield key=value,...`) could not be
    /// parsed.
    #[error("invalid shield assumptions {spec:?}: {problem}")]
    ShieldSpec {
        /// The string given.
        spec: String,
        /// What is wrong.
        problem: String,
    },
    /// An action index is outside the action set.
    #[error("action {action} is out of range for the {set} action set ({count} actions)")]
    ActionOutOfRange {
        /// The index given.
        action: usize,
        /// The action set's name.
        set: &'static str,
        /// How many actions the set has.
        count: usize,
    },
    /// A policy cannot drive this action set.
    #[error("policy {policy} cannot drive the {set} action set")]
    Unsupported {
        /// The policy.
        policy: String,
        /// The action set.
        set: &'static str,
    },
    /// A caller-provided buffer has the wrong length.
    #[error("observation buffer has length {got}, expected {expected}")]
    BufferLength {
        /// Length needed.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// A plugged-in policy failed.
    #[error("policy failed: {0}")]
    Policy(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// Evaluation settings are out of range.
    #[error("invalid evaluation settings: {0}")]
    EvalConfig(String),
    /// Batched stepping ([`crate::VecEnv`]) was asked for no environments,
    /// or given a number of actions other than its environments'.
    #[error("vectorized environments: {0}")]
    VecEnv(String),
}

impl SimError {
    pub(crate) fn invalid(what: &str, problem: impl Into<String>) -> Self {
        Self::Invalid {
            what: what.to_owned(),
            problem: problem.into(),
        }
    }
}
