//! The one configuration schema of a crossroads run, and its layered loading.
//!
//! Every role reads the same file, so one file describes a run. Layers, each
//! overriding the one before: built-in defaults, a TOML file, `CROSSROADS_*`
//! environment variables (`CROSSROADS_<SECTION>__<KEY>`, double underscore
//! between section and key), then command-line `--set section.key=value`
//! flags and a role's own flags. Unknown keys, wrong types and out-of-range
//! values are errors that name where the value came from, the key and the
//! problem.

use std::fmt;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use figment::providers::{Env, Format, Serialized, Toml};
use figment::value::Value;
use figment::value::{Dict, Map};
use figment::{Figment, Metadata, Profile, Provider, Source};
use serde::{Deserialize, Serialize};

pub mod actor;
pub mod learner;
pub mod train;

/// Action set names the simulator knows (`crossroads_sim::ActionSet`; this
/// crate does not depend on the simulator).
pub(crate) const ACTION_SETS: [&str; 3] = ["ttg", "sequential", "creep"];

/// Whether `value` is one of `allowed`, and the problem to report if not.
pub(crate) fn one_of(value: &str, allowed: &[&str]) -> (bool, String) {
    (
        allowed.contains(&value),
        format!("must be one of {}, got {value:?}", allowed.join(", ")),
    )
}

pub use actor::{ActorConfig, ActorTransport};
pub use learner::{LearnerConfig, OptimizerKind, TargetUpdate, Trunk};
pub use train::TrainConfig;

const DEFAULTS: &str = "defaults";
const COMMAND_LINE: &str = "command line";

/// Prefix of the environment variables that override the config.
pub const ENV_PREFIX: &str = "CROSSROADS_";

/// The whole configuration of a run, one section per concern.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Threads of the process.
    pub runtime: RuntimeConfig,
    /// Logs and metrics.
    pub telemetry: TelemetryConfig,
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

/// Threads of the process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RuntimeConfig {
    /// Threads of the async runtime that serves gRPC, metrics and transports.
    /// 1 to 256.
    pub worker_threads: usize,
    /// Threads for number crunching (libtorch intra-op, rayon simulation
    /// pools); 0 means one per core. At most 1024.
    pub compute_threads: usize,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self {
            worker_threads: 2,
            compute_threads: 0,
        }
    }
}

/// How log lines are written to standard error.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// Human-readable lines.
    #[default]
    Text,
    /// One JSON object per line, for log collectors.
    Json,
}

/// Logs and metrics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TelemetryConfig {
    /// `text` or `json`. The level comes from `RUST_LOG` (default `info`).
    pub log_format: LogFormat,
    /// Whether the process serves Prometheus metrics.
    pub metrics: bool,
    /// Address of the `/metrics` endpoint; port 0 picks a free port.
    pub metrics_addr: SocketAddr,
}

impl Default for TelemetryConfig {
    fn default() -> Self {
        Self {
            log_format: LogFormat::Text,
            metrics: true,
            metrics_addr: SocketAddr::from(([127, 0, 0, 1], 9100)),
        }
    }
}

/// How importance weights are normalized.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WeightNormalization {
    /// Divide by the largest weight any item of the table could get (that
    /// of the lowest priority), so weights are comparable across batches.
    #[default]
    Table,
    /// Divide by the largest weight in the sampled batch (the PER paper's
    /// practice).
    Batch,
}

/// The replay server (`crossroads replay`): one prioritized table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReplayConfig {
    /// gRPC address to serve on; port 0 picks a free port.
    pub listen: SocketAddr,
    /// Name of the table; requests naming another table are rejected.
    pub table: String,
    /// Items kept; the oldest is evicted first (FIFO) when full.
    /// 1 to 100,000,000.
    pub capacity: u64,
    /// Priority exponent: items are sampled with probability p^alpha / sum;
    /// 0 samples uniformly. 0 to 1.
    pub alpha: f64,
    /// Priorities below this are raised to it before the exponent, so no
    /// item becomes unsampleable and weights stay finite. Above 0.
    pub min_priority: f64,
    /// Importance weights divided by the table's or the batch's largest.
    pub weight_normalization: WeightNormalization,
    /// Items inserted before the first sample is allowed (counted over the
    /// table's life, so a value above `capacity` only delays sampling).
    pub min_size_to_sample: u64,
    /// Target samples per inserted item (the learner neither overfits a
    /// small buffer nor falls behind); 0 turns the ratio off.
    pub samples_per_insert: f64,
    /// How far, in samples, the ratio may drift either way before inserts
    /// or samples wait. At least max(1, samples_per_insert) when the ratio
    /// is on.
    pub rate_tolerance: f64,
    /// Longest an insert waits for the rate limiter, milliseconds.
    pub insert_timeout_ms: u64,
    /// Longest a sample waits for the rate limiter when the request does
    /// not say, milliseconds.
    pub sample_timeout_ms: u64,
    /// Largest gRPC message accepted, bytes (64 KiB to 1 GiB).
    pub max_message_bytes: usize,
    /// Largest batch accepted, transitions.
    pub max_batch_transitions: u32,
    /// Largest sample or priority update, items.
    pub max_sample_batch: u32,
    /// Seed of the sampler's random numbers.
    pub seed: u64,
    /// Where snapshots are written and restored from; none disables them.
    pub snapshot_dir: Option<PathBuf>,
    /// Seconds between periodic snapshots; 0 writes them only on shutdown
    /// and on request.
    pub snapshot_interval_secs: u64,
    /// Snapshots kept (the newest good ones); at least 1.
    pub snapshot_keep: u32,
    /// Whether to restore the newest good snapshot at start.
    pub restore: bool,
    /// Whether to take batches over iceoryx2 shared memory from actors on
    /// this host (beside gRPC).
    pub shm_ingest: bool,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 50051)),
            table: "transitions".to_owned(),
            capacity: 1_000_000,
            alpha: 0.6,
            min_priority: 1e-6,
            weight_normalization: WeightNormalization::Table,
            min_size_to_sample: 1_000,
            samples_per_insert: 0.0,
            rate_tolerance: 1_000.0,
            insert_timeout_ms: 30_000,
            sample_timeout_ms: 10_000,
            max_message_bytes: 64 << 20,
            max_batch_transitions: 16_384,
            max_sample_batch: 4_096,
            seed: 1,
            snapshot_dir: None,
            snapshot_interval_secs: 300,
            snapshot_keep: 2,
            restore: true,
            shm_ingest: true,
        }
    }
}

/// How roles reach each other.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TransportConfig {
    /// The replay server as clients (actors, learner) reach it, e.g.
    /// `http://replay:50051`.
    pub replay_endpoint: String,
    /// The learner's gRPC service as actors reach it for weights, e.g.
    /// `http://learner:50052`.
    pub learner_endpoint: String,
    /// Longest wait for a connection, milliseconds.
    pub connect_timeout_ms: u64,
    /// Longest wait for an answer to a unary call, milliseconds.
    pub request_timeout_ms: u64,
    /// First wait before retrying a failed call, milliseconds; doubled on
    /// each failure up to `max_backoff_ms`.
    pub initial_backoff_ms: u64,
    /// Longest wait between retries, milliseconds.
    pub max_backoff_ms: u64,
    /// Prefix of iceoryx2 service names; processes that talk over shared
    /// memory must agree on it (and share /dev/shm and /tmp/iceoryx2).
    pub shm_prefix: String,
    /// Largest number of publishers (actor processes) per shared-memory
    /// service.
    pub shm_max_publishers: usize,
    /// Batches a subscriber's queue holds before publishers wait.
    pub shm_buffer: usize,
    /// First size of a publisher's shared-memory slot, bytes; slots grow
    /// for bigger batches.
    pub shm_initial_batch_bytes: usize,
    /// Longest a publisher waits for room in a full queue before the send
    /// fails, milliseconds.
    pub shm_send_timeout_ms: u64,
}

impl Default for TransportConfig {
    fn default() -> Self {
        Self {
            replay_endpoint: "http://127.0.0.1:50051".to_owned(),
            learner_endpoint: "http://127.0.0.1:50052".to_owned(),
            connect_timeout_ms: 5_000,
            request_timeout_ms: 30_000,
            initial_backoff_ms: 100,
            max_backoff_ms: 5_000,
            shm_prefix: "crossroads".to_owned(),
            shm_max_publishers: 64,
            shm_buffer: 64,
            shm_initial_batch_bytes: 64 << 10,
            shm_send_timeout_ms: 5_000,
        }
    }
}

impl Config {
    /// Checks values that the types alone cannot: ranges and relations.
    /// Returns every problem found, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = Vec::new();
        let mut check = |ok: bool, key: &str, problem: String| {
            if !ok {
                problems.push((key.to_owned(), problem));
            }
        };
        let rt = &self.runtime;
        check(
            (1..=256).contains(&rt.worker_threads),
            "runtime.worker_threads",
            format!("must be between 1 and 256, got {}", rt.worker_threads),
        );
        check(
            rt.compute_threads <= 1024,
            "runtime.compute_threads",
            format!(
                "must be at most 1024 (0 = one per core), got {}",
                rt.compute_threads
            ),
        );

        let r = &self.replay;
        check(
            !r.table.is_empty() && r.table.len() <= 64,
            "replay.table",
            format!("must be 1 to 64 characters, got {:?}", r.table),
        );
        check(
            (1..=100_000_000).contains(&r.capacity),
            "replay.capacity",
            format!("must be between 1 and 100000000, got {}", r.capacity),
        );
        check(
            (0.0..=1.0).contains(&r.alpha),
            "replay.alpha",
            format!("must be between 0 and 1, got {}", r.alpha),
        );
        check(
            r.min_priority > 0.0 && r.min_priority.is_finite(),
            "replay.min_priority",
            format!("must be finite and above 0, got {}", r.min_priority),
        );
        check(
            r.samples_per_insert >= 0.0 && r.samples_per_insert.is_finite(),
            "replay.samples_per_insert",
            format!(
                "must be finite and at least 0 (0 = off), got {}",
                r.samples_per_insert
            ),
        );
        let min_tolerance = r.samples_per_insert.max(1.0);
        check(
            r.samples_per_insert == 0.0
                || (r.rate_tolerance >= min_tolerance && r.rate_tolerance.is_finite()),
            "replay.rate_tolerance",
            format!(
                "must be at least max(1, replay.samples_per_insert) = {min_tolerance}, got {}",
                r.rate_tolerance
            ),
        );
        for (key, value) in [
            ("replay.insert_timeout_ms", r.insert_timeout_ms),
            ("replay.sample_timeout_ms", r.sample_timeout_ms),
        ] {
            check(
                (1..=3_600_000).contains(&value),
                key,
                format!("must be between 1 and 3600000, got {value}"),
            );
        }
        check(
            (64 << 10..=1 << 30).contains(&r.max_message_bytes),
            "replay.max_message_bytes",
            format!(
                "must be between 65536 and 1073741824, got {}",
                r.max_message_bytes
            ),
        );
        check(
            r.max_batch_transitions >= 1,
            "replay.max_batch_transitions",
            "must be at least 1".to_owned(),
        );
        check(
            (1..=1 << 20).contains(&r.max_sample_batch),
            "replay.max_sample_batch",
            format!("must be between 1 and 1048576, got {}", r.max_sample_batch),
        );
        check(
            r.snapshot_keep >= 1,
            "replay.snapshot_keep",
            "must be at least 1".to_owned(),
        );

        let t = &self.transport;
        for (key, url) in [
            ("transport.replay_endpoint", &t.replay_endpoint),
            ("transport.learner_endpoint", &t.learner_endpoint),
        ] {
            check(
                url.starts_with("http://") || url.starts_with("https://"),
                key,
                format!("must be an http:// or https:// URL, got {url:?}"),
            );
        }
        for (key, value) in [
            ("transport.connect_timeout_ms", t.connect_timeout_ms),
            ("transport.request_timeout_ms", t.request_timeout_ms),
            ("transport.initial_backoff_ms", t.initial_backoff_ms),
            ("transport.shm_send_timeout_ms", t.shm_send_timeout_ms),
        ] {
            check(
                (1..=3_600_000).contains(&value),
                key,
                format!("must be between 1 and 3600000, got {value}"),
            );
        }
        check(
            t.max_backoff_ms >= t.initial_backoff_ms && t.max_backoff_ms <= 3_600_000,
            "transport.max_backoff_ms",
            format!(
                "must be between transport.initial_backoff_ms ({}) and 3600000, got {}",
                t.initial_backoff_ms, t.max_backoff_ms
            ),
        );
        check(
            !t.shm_prefix.is_empty()
                && t.shm_prefix.len() <= 128
                && t.shm_prefix
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./".contains(c)),
            "transport.shm_prefix",
            format!(
                "must be 1 to 128 characters of letters, digits, '-', '_', '.', '/', got {:?}",
                t.shm_prefix
            ),
        );
        check(
            (1..=4096).contains(&t.shm_max_publishers),
            "transport.shm_max_publishers",
            format!("must be between 1 and 4096, got {}", t.shm_max_publishers),
        );
        check(
            (1..=65_536).contains(&t.shm_buffer),
            "transport.shm_buffer",
            format!("must be between 1 and 65536, got {}", t.shm_buffer),
        );
        check(
            (1024..=1 << 30).contains(&t.shm_initial_batch_bytes),
            "transport.shm_initial_batch_bytes",
            format!(
                "must be between 1024 and 1073741824, got {}",
                t.shm_initial_batch_bytes
            ),
        );
        problems.extend(self.actor.validate());
        problems.extend(self.learner.validate());
        problems.extend(self.train.validate());
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

    /// Merges the layers, deserializes and validates.
    pub fn load(&self) -> Result<Config, ConfigError> {
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

        let config: Config = figment.extract().map_err(|e| {
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
            Ok(config)
        } else {
            Err(ConfigError::Invalid(problems))
        }
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
    let metadata = e.metadata.as_ref().or_else(|| figment.find_metadata(&key));
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
