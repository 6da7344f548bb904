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
    /// Threads of the rayon pool that steps simulators (and of libtorch
    /// where `torch_threads` is 0); 0 means one per core. At most 1024.
    pub compute_threads: usize,
    /// libtorch intra-op threads of the thread that runs a network (an
    /// actor's inference, the learner's updates, doctor, eval); 0 means
    /// `compute_threads`' choice. 1 by default: this project's networks
    /// are small, and with OpenMP threads that sleep between operations
    /// (`OMP_WAIT_POLICY=passive`, the default) every operation spread
    /// over two threads pays a wake-up. Measured on 2 cores: MLP update
    /// 463 updates/s on 1 thread, 323 on 2; an actor at M = 32 stores
    /// 1.3x more transitions/s; and one thread keeps its pace beside a
    /// busy process. At most 1024.
    pub torch_threads: usize,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self {
            worker_threads: 2,
            compute_threads: 0,
            torch_threads: 1,
        }
    }
}

impl RuntimeConfig {
    /// libtorch's intra-op threads for a network's thread, if set: the
    /// caller applies it with `tch::set_num_threads` on that thread.
    pub fn torch_threads(&self) -> Option<usize> {
        match (self.torch_threads, self.compute_threads) {
            (0, 0) => None,
            (0, n) | (n, _) => Some(n),
        }
    }

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
        problems.check(
            self.torch_threads <= 1024,
            "torch_threads",
            format!(
                "must be at most 1024 (0 = as compute_threads), got {}",
                self.torch_threads
            ),
        );
        problems.into_vec()
    }
}
