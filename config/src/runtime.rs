//! `[runtime]`: the process's threads.

use serde::{Deserialize, Serialize};

use super::Checks;

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

impl RuntimeConfig {
    /// Range and relation checks, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = Checks::new("runtime");
        problems.within("worker_threads", self.worker_threads, 1..=256);
        problems.check(
            self.compute_threads <= 1024,
            "compute_threads",
            format!(
                "must be at most 1024 (0 = one per core), got {}",
                self.compute_threads
            ),
        );
        problems.into_vec()
    }
}
