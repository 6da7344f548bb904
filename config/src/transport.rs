//! `[transport]`: how roles reach each other: addresses, shared-memory
//! services, timeouts and retries.

use serde::{Deserialize, Serialize};

use super::Checks;

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
        problems.into_vec()
    }
}
