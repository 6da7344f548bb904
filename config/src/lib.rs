//! The one configuration schema of a crossroads run, and its layered loading.
//!
//! Every role reads the same file, so one file describes a run. Layers, each
//! overriding the one before: built-in defaults, a TOML file, `CROSSROADS_*`
//! environment variables (`CROSSROADS_<SECTION>__<KEY>`, double underscore
//! between section and key), then command-line `--set section.key=value`
//! flags and a role's own flags. Unknown keys, wrong types and out-of-range
//! values are errors that name where the value came from, the key and the
//! problem.
//!
//! A built-in experiment ([`ConfigLoader::base`]) may lie between the
//! defaults and the file. Each section is a module with its struct (unknown
//! keys refused), its defaults and a `validate` that reports every problem
//! under its dotted key; a [`ConfigProblem`] names origin, key and problem.
//! Keys of the older schema ([`MOVED_KEYS`]) are read at their new place
//! with a warning, and refused when two disagree.

use std::fmt;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use figment::providers::{Env, Format, Serialized, Toml};
use figment::value::Value;
use figment::value::{Dict, Map};
use figment::{Figment, Metadata, Profile, Provider, Source};
use serde::{Deserialize, Serialize};

pub mod actor;
pub mod learner;
pub mod replay;
pub mod runtime;
pub mod sim;
pub mod telemetry;
pub mod train;
pub mod transport;

pub(crate) use crossroads_types::spec::ACTION_SETS;

/// The problems a section's `validate` finds, each under its dotted key
/// (`section.key`).
pub(crate) struct Checks {
    section: &'static str,
    problems: Vec<(String, String)>,
}

impl Checks {
    pub(crate) fn new(section: &'static str) -> Self {
        Self {
            section,
            problems: Vec::new(),
        }
    }

    /// Records `problem` under `key` unless `ok`.
    pub(crate) fn check(&mut self, ok: bool, key: &str, problem: String) {
        if !ok {
            self.problems
                .push((format!("{}.{key}", self.section), problem));
        }
    }

    /// Records a problem unless `value` lies in `range` (both ends in).
    pub(crate) fn within<T>(&mut self, key: &str, value: T, range: RangeInclusive<T>)
    where
        T: PartialOrd + fmt::Display,
    {
        let problem = format!(
            "must be between {} and {}, got {value}",
            range.start(),
            range.end()
        );
        self.check(range.contains(&value), key, problem);
    }

    /// Records a problem unless `value` is one of `allowed`.
    pub(crate) fn one_of(&mut self, key: &str, value: &str, allowed: &[&str]) {
        self.check(
            allowed.contains(&value),
            key,
            format!("must be one of {}, got {value:?}", allowed.join(", ")),
        );
    }

    pub(crate) fn into_vec(self) -> Vec<(String, String)> {
        self.problems
    }
}

pub use actor::{ActorConfig, ActorTransport};
pub use crossroads_types::TrunkKind;
pub use learner::{LearnerConfig, OptimizerKind, TargetUpdate};
pub use replay::{ReplayConfig, WeightNormalization};
pub use runtime::{DeviceSetting, PrecisionSetting, RuntimeConfig};
pub use sim::SimConfig;
pub use telemetry::{LogFormat, TelemetryConfig};
pub use train::TrainConfig;
pub use transport::{AuthConfig, TlsConfig, TransportConfig};

const DEFAULTS: &str = "defaults";
const COMMAND_LINE: &str = "command line";

/// Prefix of the environment variables that override the config.
pub const ENV_PREFIX: &str = "CROSSROADS_";

/// The schema of [`Config`]: every section and key with its doc comment,
/// type and allowed values. `docs/reference/config.md` is generated from
/// it (`crossroads docs`), so the reference cannot drift from the code.
pub fn schema() -> schemars::Schema {
    schemars::schema_for!(Config)
}

/// The whole configuration of a run, one section per concern.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Threads of the process.
    pub runtime: RuntimeConfig,
    /// Logs and metrics.
    pub telemetry: TelemetryConfig,
    /// What the run simulates and learns on: scenario, action set and
    /// observation, stated once for every role.
    pub sim: SimConfig,
    /// The replay server: its table, rate limiter, limits and snapshots.
    pub replay: ReplayConfig,
    /// How roles reach each other: the replay server's address, shared
    /// memory services, timeouts and retries.
    pub transport: TransportConfig,
    /// Actor processes: environments, exploration, n-step assembly and
    /// transport of transitions.
    pub actor: ActorConfig,
    /// The learner: network, optimizer, targets, weight broadcast and
    /// checkpoints.
    pub learner: LearnerConfig,
    /// `crossroads train`: actors started, evaluations, budget, target.
    pub train: TrainConfig,
}

impl Config {
    /// Checks values that the types alone cannot: ranges and relations.
    /// Returns every problem found, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = self.runtime.validate();
        problems.extend(self.sim.validate());
        problems.extend(self.replay.validate());
        problems.extend(self.transport.validate());
        problems.extend(self.actor.validate());
        problems.extend(self.learner.validate());
        problems.extend(self.train.validate());
        if self.learner.go_label_weight != 1.0 && self.sim.action_set == "sequential" {
            problems.push((
                "learner.go_label_weight".to_owned(),
                format!(
                    "weighs the absorbing go of ttg or creep actions, and sim.action_set is \
                     sequential (no absorbing go): leave it at 1, got {}",
                    self.learner.go_label_weight
                ),
            ));
        }
        problems
    }

    /// The effective configuration as TOML, as `crossroads config show`
    /// prints it and as roles log it at start.
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot render config: {e}"))
    }
}

/// One problem with one key.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigProblem {
    /// Where the offending value came from, e.g. `config file run.toml` or
    /// `environment variable CROSSROADS_RUNTIME__WORKER_THREADS`.
    pub origin: String,
    /// Dotted key, e.g. `runtime.worker_threads`.
    pub key: String,
    /// What is wrong with it.
    pub problem: String,
}

impl fmt::Display for ConfigProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: key `{}`: {}", self.origin, self.key, self.problem)
    }
}

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The config file named by the user could not be read.
    #[error("cannot read config file {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A `--set` flag is not of the form `section.key=value`.
    #[error("invalid --set {0:?}: expected section.key=value")]
    BadOverride(String),
    /// One or more keys are unknown, mistyped or out of range.
    #[error("invalid configuration:\n  {}", .0.iter().map(ToString::to_string).collect::<Vec<_>>().join("\n  "))]
    Invalid(Vec<ConfigProblem>),
}

impl ConfigError {
    /// The problems, if the error is about keys.
    pub fn problems(&self) -> &[ConfigProblem] {
        match self {
            ConfigError::Invalid(p) => p,
            _ => &[],
        }
    }
}

/// Builds a [`Config`] from its layers. Later layers win.
#[derive(Debug, Default, Clone)]
pub struct ConfigLoader {
    base: Option<(String, String)>,
    file: Option<PathBuf>,
    env: bool,
    sets: Vec<String>,
    flags: Vec<(String, Value)>,
}

impl ConfigLoader {
    /// Defaults, plus the `CROSSROADS_*` environment variables.
    pub fn new() -> Self {
        Self {
            env: true,
            ..Self::default()
        }
    }

    /// Ignores the environment (for tests and tools that want only a file).
    pub fn without_env(mut self) -> Self {
        self.env = false;
        self
    }

    /// A built-in TOML text under `name` (an experiment's settings, say),
    /// applied over the defaults and under the file and everything else.
    pub fn base(mut self, name: impl Into<String>, toml: impl Into<String>) -> Self {
        self.base = Some((name.into(), toml.into()));
        self
    }

    /// Reads this TOML file (it must exist).
    pub fn file(mut self, path: Option<impl AsRef<Path>>) -> Self {
        self.file = path.map(|p| p.as_ref().to_path_buf());
        self
    }

    /// Adds `--set section.key=value` overrides, applied after the
    /// environment. Values parse as TOML-like scalars or arrays; anything
    /// else is a string.
    pub fn sets<I, S>(mut self, sets: I) -> Self
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        self.sets.extend(sets.into_iter().map(Into::into));
        self
    }

    /// Adds a role's own flag, e.g. `("replay.capacity", 100_000)`; applied
    /// last.
    pub fn flag(mut self, key: &str, value: impl Serialize) -> Self {
        if let Ok(v) = Value::serialize(value) {
            self.flags.push((key.to_owned(), v));
        }
        self
    }

    /// Merges the layers, deserializes and validates. Keys of the older
    /// schema ([`MOVED_KEYS`]) are read at their new place with a warning
    /// on standard error (the log is not set up yet: its format is config).
    pub fn load(&self) -> Result<Config, ConfigError> {
        let (config, notes) = self.load_with_notes()?;
        for note in &notes {
            eprintln!("warning: {note}");
        }
        Ok(config)
    }

    /// [`Self::load`], returning the deprecation warnings instead of
    /// printing them.
    pub fn load_with_notes(&self) -> Result<(Config, Vec<String>), ConfigError> {
        let mut figment = Figment::from(Named {
            name: DEFAULTS.into(),
            inner: Serialized::defaults(Config::default()),
        });
        if let Some((name, text)) = &self.base {
            figment = figment.merge(Named {
                name: name.clone().into(),
                inner: Toml::string(text),
            });
        }
        if let Some(path) = &self.file {
            // figment treats a missing file as empty; a file the user named
            // must exist.
            std::fs::metadata(path).map_err(|source| ConfigError::Read {
                path: path.clone(),
                source,
            })?;
            figment = figment.merge(Toml::file_exact(path));
        }
        if self.env {
            // Only section-scoped variables are config; others with the same
            // prefix (CROSSROADS_WHEEL_CACHE, say) are not ours to reject.
            figment = figment.merge(
                Env::prefixed(ENV_PREFIX)
                    .filter(|k| k.as_str().contains("__"))
                    .split("__"),
            );
        }
        for set in &self.sets {
            let (key, value) = set
                .split_once('=')
                .filter(|(k, _)| !k.trim().is_empty())
                .ok_or_else(|| ConfigError::BadOverride(set.clone()))?;
            let value: Value = value.trim().parse().unwrap_or_else(|_| Value::from(value));
            figment = figment.merge(Named {
                name: COMMAND_LINE.into(),
                inner: Serialized::default(key.trim(), value),
            });
        }
        for (key, value) in &self.flags {
            figment = figment.merge(Named {
                name: COMMAND_LINE.into(),
                inner: Serialized::default(key, value),
            });
        }

        let (merged, notes) = move_legacy_keys(&figment)?;
        let config: Config = merged.as_ref().unwrap_or(&figment).extract().map_err(|e| {
            ConfigError::Invalid(e.into_iter().map(|e| problem_of(&figment, &e)).collect())
        })?;
        let problems: Vec<_> = config
            .validate()
            .into_iter()
            .map(|(key, problem)| ConfigProblem {
                origin: origin_of(figment.find_metadata(&key), &key),
                key,
                problem,
            })
            .collect();
        if problems.is_empty() {
            Ok((config, notes))
        } else {
            Err(ConfigError::Invalid(problems))
        }
    }
}

/// Keys of the older schema that said one thing in two places, and the one
/// key that now says it. Files with them still load, with a warning per
/// key; two of them that disagree, or one that disagrees with the new key,
/// are refused.
pub const MOVED_KEYS: [(&str, &str); 6] = [
    ("actor.scenario", "sim.scenario"),
    ("learner.scenario", "sim.scenario"),
    ("actor.action_set", "sim.action_set"),
    ("learner.action_set", "sim.action_set"),
    ("learner.observation", "sim.observation"),
    ("train.actors", "actor.count"),
];

/// How late a layer comes (later layers win): defaults, the built-in
/// base, the file, the environment, the command line.
fn layer_rank(metadata: Option<&Metadata>) -> u8 {
    match metadata {
        None => 0,
        Some(m) if m.name == DEFAULTS => 0,
        Some(m) if matches!(m.source, Some(Source::File(_))) => 2,
        Some(m) if m.name.contains("environment") => 3,
        Some(m) if m.name == COMMAND_LINE => 4,
        Some(_) => 1,
    }
}

/// A merged configuration with [`MOVED_KEYS`] moved to their new place
/// (`None` when no layer has an old key), and a warning per old key found.
/// Between an old key and its new one (or two old ones), the later layer
/// wins as for any key; two that disagree in the same layer are refused.
fn move_legacy_keys(figment: &Figment) -> Result<(Option<Figment>, Vec<String>), ConfigError> {
    let found: Vec<_> = MOVED_KEYS
        .iter()
        .filter_map(|&(old, new)| figment.find_value(old).ok().map(|v| (old, new, v)))
        .collect();
    if found.is_empty() {
        return Ok((None, Vec::new()));
    }
    let mut data: Dict = figment.extract().map_err(|e| {
        ConfigError::Invalid(e.into_iter().map(|e| problem_of(figment, &e)).collect())
    })?;
    let mut problems = Vec::new();
    let mut notes = Vec::new();
    let mut news: Vec<&str> = found.iter().map(|&(_, new, _)| new).collect();
    news.sort_unstable();
    news.dedup();
    for new in news {
        // Every place that says this key: its old names, and the new one
        // when a layer above the defaults sets it.
        let mut says: Vec<(&str, Value, u8)> = found
            .iter()
            .filter(|&&(_, n, _)| n == new)
            .map(|(old, _, v)| (*old, v.clone(), layer_rank(figment.find_metadata(old))))
            .collect();
        let new_rank = layer_rank(figment.find_metadata(new));
        if new_rank > 0
            && let Ok(v) = figment.find_value(new)
        {
            says.push((new, v, new_rank));
        }
        let top = says.iter().map(|&(_, _, r)| r).max().unwrap_or(0);
        let latest: Vec<_> = says.iter().filter(|&&(_, _, r)| r == top).collect();
        let (first, value, _) = latest[0];
        if let Some((other, theirs, _)) = latest.iter().find(|(_, v, _)| v != value) {
            let (old, said, other, theirs) = if *other == new {
                (*first, value, *other, theirs)
            } else {
                (*other, theirs, *first, value)
            };
            let problem = if other == new {
                format!(
                    "moved to `{new}`, which says {} here while `{old}` says {}; remove `{old}`",
                    show(theirs),
                    show(said)
                )
            } else {
                format!(
                    "says {}, but `{other}` says {}; both moved to `{new}`: state it once there",
                    show(said),
                    show(theirs)
                )
            };
            problems.push(ConfigProblem {
                origin: origin_of(figment.find_metadata(old), old),
                key: old.to_owned(),
                problem,
            });
            continue;
        }
        let (value, winner) = (value.clone(), *first);
        for (old, _, _) in says.iter().filter(|&&(k, _, _)| k != new) {
            let origin = origin_of(figment.find_metadata(old), old);
            let read = if winner == new {
                format!("was overridden by `{new}`")
            } else {
                format!("was read as `{new}`")
            };
            notes.push(format!(
                "{origin}: key `{old}` is deprecated and {read}; write `{new}` once instead"
            ));
            let (section, key) = old.split_once('.').expect("dotted");
            if let Some(Value::Dict(_, section)) = data.get_mut(section) {
                section.remove(key);
            }
        }
        let (section, key) = new.split_once('.').expect("dotted");
        if let Some(Value::Dict(_, section)) = data.get_mut(section) {
            section.insert(key.to_owned(), value);
        } else {
            let mut dict = Dict::new();
            dict.insert(key.to_owned(), value);
            data.insert(section.to_owned(), Value::from(dict));
        }
    }
    if !problems.is_empty() {
        return Err(ConfigError::Invalid(problems));
    }
    Ok((Some(Figment::from(Serialized::defaults(data))), notes))
}

/// A value as the user wrote it, for messages.
fn show(value: &Value) -> String {
    match value {
        Value::String(_, s) => format!("{s:?}"),
        Value::Bool(_, b) => b.to_string(),
        Value::Num(_, n) => n.to_i128().map_or_else(
            || {
                n.to_f64()
                    .map_or_else(|| format!("{n:?}"), |f| f.to_string())
            },
            |i| i.to_string(),
        ),
        other => format!("{other:?}"),
    }
}

/// A provider under a name of ours, so errors can say where a value came
/// from ("defaults", "command line") rather than "Serialized".
struct Named<P> {
    name: std::borrow::Cow<'static, str>,
    inner: P,
}

impl<P: Provider> Provider for Named<P> {
    fn metadata(&self) -> Metadata {
        Metadata::named(self.name.clone())
    }

    fn data(&self) -> Result<Map<Profile, Dict>, figment::Error> {
        self.inner.data()
    }
}

fn problem_of(figment: &Figment, e: &figment::Error) -> ConfigProblem {
    use figment::error::Kind;
    // For an unknown field the path already ends with the field's name.
    let key = e.path.join(".");
    let problem = match &e.kind {
        Kind::UnknownField(_, expected) => {
            format!("unknown key; expected one of: {}", expected.join(", "))
        }
        kind => kind.to_string(),
    };
    // The layer the key came from (`figment` is the layered one, also when
    // the error is of the merged figment that moved legacy keys).
    let metadata = figment.find_metadata(&key).or(e.metadata.as_ref());
    ConfigProblem {
        origin: origin_of(metadata, &key),
        key,
        problem,
    }
}

fn origin_of(metadata: Option<&Metadata>, key: &str) -> String {
    let Some(md) = metadata else {
        return "configuration".to_owned();
    };
    match &md.source {
        Some(Source::File(path)) => format!("config file {}", path.display()),
        _ if md.name.contains("environment") => {
            let var = format!("{ENV_PREFIX}{}", key.replace('.', "__").to_uppercase());
            format!("environment variable {var}")
        }
        _ => md.name.to_string(),
    }
}
