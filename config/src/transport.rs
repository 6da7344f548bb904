//! `[transport]`: how roles reach each other: addresses, shared-memory
//! services, timeouts and retries; `[transport.tls]` and
//! `[transport.auth]`: TLS on the gRPC endpoints and the token their
//! state-changing calls need. Both are off by default (plain HTTP/2, no
//! token), which suits loopback; reading the files they name is the
//! roles' job at start (`crossroads_transport::security`), so a config
//! naming files of another machine still loads and shows.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::Checks;

/// How roles reach each other.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
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
    /// TLS on every gRPC endpoint (`[transport.tls]`); off by default.
    pub tls: TlsConfig,
    /// The token state-changing calls carry (`[transport.auth]`); off by
    /// default.
    pub auth: AuthConfig,
}

/// TLS on the gRPC endpoints, as the servers (replay, learner) and their
/// clients (actors, learner, the CLI) of one run use it. Files are PEM.
/// One file describes a run, so a process reads the server half when it
/// serves and the client half when it calls.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TlsConfig {
    /// Server side: the certificate chain the replay and learner servers
    /// present. Set with `key_file`, the servers speak TLS only, and the
    /// endpoints must be `https://`.
    pub cert_file: Option<PathBuf>,
    /// Server side: the private key of `cert_file` (PKCS#8, PKCS#1 or
    /// SEC1). A secret: mount it, keep it out of images and repositories.
    pub key_file: Option<PathBuf>,
    /// Server side: CA certificates that sign client certificates. When
    /// set, every client must present a certificate signed by one of them
    /// (mutual TLS); connections without one are refused at the handshake.
    pub client_ca_file: Option<PathBuf>,
    /// Client side: CA certificates trusted for `https://` endpoints
    /// (there are no built-in roots); required when an endpoint is
    /// `https://`.
    pub ca_file: Option<PathBuf>,
    /// Client side: the certificate a client presents to servers that
    /// require one (`client_ca_file` on their side). Set with
    /// `client_key_file`.
    pub client_cert_file: Option<PathBuf>,
    /// Client side: the private key of `client_cert_file`. A secret.
    pub client_key_file: Option<PathBuf>,
    /// Client side: the name checked against the servers' certificates
    /// instead of the endpoint's host, e.g. when reaching them by an
    /// address their certificate does not name.
    pub server_name: Option<String>,
}

impl TlsConfig {
    /// Whether this run's servers speak TLS (`cert_file` is set).
    pub fn serves_tls(&self) -> bool {
        self.cert_file.is_some()
    }

    /// The URL scheme of this run's servers: `https` when they speak TLS.
    pub fn scheme(&self) -> &'static str {
        if self.serves_tls() { "https" } else { "http" }
    }
}

/// The token every state-changing gRPC call must carry as
/// `authorization: Bearer <token>`, shared by the replay and learner
/// services and their clients. The token is never written in the TOML
/// file: it comes from a file (`token_file`, e.g. a mounted secret) or from
/// the environment variable named by `token_env`. With neither, calls need
/// no token.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct AuthConfig {
    /// A file holding the token (surrounding whitespace is ignored). Wins
    /// over `token_env`.
    pub token_file: Option<PathBuf>,
    /// The environment variable read for the token when `token_file` is
    /// not set (unset or empty: no token); `""` reads none.
    pub token_env: String,
}

impl Default for AuthConfig {
    fn default() -> Self {
        Self {
            token_file: None,
            token_env: "CROSSROADS_TOKEN".to_owned(),
        }
    }
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
            tls: TlsConfig::default(),
            auth: AuthConfig::default(),
        }
    }
}

impl TransportConfig {
    /// Range and relation checks, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = Checks::new("transport");
        for (key, url) in [
            ("replay_endpoint", &self.replay_endpoint),
            ("learner_endpoint", &self.learner_endpoint),
        ] {
            problems.check(
                url.starts_with("http://") || url.starts_with("https://"),
                key,
                format!("must be an http:// or https:// URL, got {url:?}"),
            );
        }
        for (key, value) in [
            ("connect_timeout_ms", self.connect_timeout_ms),
            ("request_timeout_ms", self.request_timeout_ms),
            ("initial_backoff_ms", self.initial_backoff_ms),
            ("shm_send_timeout_ms", self.shm_send_timeout_ms),
        ] {
            problems.within(key, value, 1..=3_600_000);
        }
        problems.check(
            self.max_backoff_ms >= self.initial_backoff_ms && self.max_backoff_ms <= 3_600_000,
            "max_backoff_ms",
            format!(
                "must be between transport.initial_backoff_ms ({}) and 3600000, got {}",
                self.initial_backoff_ms, self.max_backoff_ms
            ),
        );
        problems.check(
            !self.shm_prefix.is_empty()
                && self.shm_prefix.len() <= 128
                && self
                    .shm_prefix
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./".contains(c)),
            "shm_prefix",
            format!(
                "must be 1 to 128 characters of letters, digits, '-', '_', '.', '/', got {:?}",
                self.shm_prefix
            ),
        );
        problems.within("shm_max_publishers", self.shm_max_publishers, 1..=4096);
        problems.within("shm_buffer", self.shm_buffer, 1..=65_536);
        problems.within(
            "shm_initial_batch_bytes",
            self.shm_initial_batch_bytes,
            1024..=1 << 30,
        );
        self.validate_security(&mut problems);
        problems.into_vec()
    }

    /// `[transport.tls]` and `[transport.auth]`: pairs set together, and
    /// endpoints that fit the servers' TLS. Files are read at start, not
    /// here.
    fn validate_security(&self, problems: &mut Checks) {
        let tls = &self.tls;
        let files: [(&str, &Option<PathBuf>); 6] = [
            ("tls.cert_file", &tls.cert_file),
            ("tls.key_file", &tls.key_file),
            ("tls.client_ca_file", &tls.client_ca_file),
            ("tls.ca_file", &tls.ca_file),
            ("tls.client_cert_file", &tls.client_cert_file),
            ("tls.client_key_file", &tls.client_key_file),
        ];
        for (key, path) in files {
            problems.check(
                path.as_deref().is_none_or(|p| p != Path::new("")),
                key,
                "must name a file, got an empty path".to_owned(),
            );
        }
        for (key, other, value, pair) in [
            ("tls.key_file", "cert_file", &tls.key_file, &tls.cert_file),
            ("tls.cert_file", "key_file", &tls.cert_file, &tls.key_file),
            (
                "tls.client_key_file",
                "client_cert_file",
                &tls.client_key_file,
                &tls.client_cert_file,
            ),
            (
                "tls.client_cert_file",
                "client_key_file",
                &tls.client_cert_file,
                &tls.client_key_file,
            ),
        ] {
            problems.check(
                value.is_some() || pair.is_none(),
                key,
                format!("must be set with transport.tls.{other}"),
            );
        }
        problems.check(
            tls.client_ca_file.is_none() || tls.cert_file.is_some(),
            "tls.client_ca_file",
            "only a TLS server checks client certificates: set transport.tls.cert_file and \
             key_file too"
                .to_owned(),
        );
        problems.check(
            tls.server_name.as_deref().is_none_or(|n| {
                !n.is_empty()
                    && n.chars()
                        .all(|c| c.is_ascii_alphanumeric() || "-._:".contains(c))
            }),
            "tls.server_name",
            format!(
                "must be a DNS name or IP address, got {:?}",
                tls.server_name.as_deref().unwrap_or_default()
            ),
        );
        for (key, url) in [
            ("replay_endpoint", &self.replay_endpoint),
            ("learner_endpoint", &self.learner_endpoint),
        ] {
            if url.starts_with("https://") {
                problems.check(
                    tls.ca_file.is_some(),
                    "tls.ca_file",
                    format!(
                        "must name the CA that signed the servers' certificates: \
                         transport.{key} is {url}"
                    ),
                );
            } else if url.starts_with("http://") {
                problems.check(
                    !tls.serves_tls(),
                    key,
                    format!(
                        "the servers speak TLS (transport.tls.cert_file is set), so clients \
                         must reach them at https://, got {url}"
                    ),
                );
            }
        }
        let env = &self.auth.token_env;
        problems.check(
            env.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !env.starts_with(|c: char| c.is_ascii_digit()),
            "auth.token_env",
            format!("must be an environment variable name (letters, digits, '_'), got {env:?}"),
        );
        problems.check(
            self.auth
                .token_file
                .as_deref()
                .is_none_or(|p| p != Path::new("")),
            "auth.token_file",
            "must name a file, got an empty path".to_owned(),
        );
    }
}
