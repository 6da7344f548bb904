//! `[runtime]`: the process's threads, number format and the learner's
//! device.

use serde::{Deserialize, Serialize};

use super::Checks;

/// Threads of the process, the number format of its networks and the
/// device of the learner's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
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
    /// over two threads pays a wake-up, and one thread keeps its pace
    /// beside a busy process (figures: reports/performance/README.md,
    /// "libtorch threads"). At most 1024.
    pub torch_threads: usize,
    /// libtorch intra-op threads of the learner's training thread; 0 (the
    /// default) means `torch_threads`. The conv experiments set 2: a conv
    /// update has products big enough to pay for splitting, where an
    /// MLP's does not (figures: reports/performance/README.md, "libtorch
    /// threads"). At most 1024.
    pub learner_torch_threads: usize,
    /// Number format of the networks an actor and the learner run:
    /// `auto` (the default) computes a conv trunk in bf16 (fp32 master
    /// weights) on a CPU with AMX-BF16 matrix units, the one case where it
    /// measured faster (reports/performance/README.md, "bf16"), and
    /// everything else in fp32; `f32` always; `bf16` asks for it on any
    /// CPU (slow without hardware bf16). `eval` and `reproduce` run fp32
    /// unless told otherwise, so a cell does not depend on the machine.
    /// On a CUDA learner (`device`) `auto` is fp32; `bf16` still asks
    /// for it there.
    pub precision: PrecisionSetting,
    /// Where the learner keeps its networks, batches, target network and
    /// optimizer state: `auto` (the default) is CUDA device 0 when
    /// libtorch was built with CUDA and a GPU is visible, else the CPU;
    /// `cpu`; `cuda` is CUDA device 0, and the learner stops at start,
    /// naming what is missing, when there is none. Only the learner uses
    /// it: actors, `eval` and `doctor`'s forward passes run on the CPU.
    /// `crossroads doctor` prints what it resolves to; building against
    /// a CUDA libtorch: docs/performance.md, "A GPU learner".
    pub device: DeviceSetting,
}

/// `runtime.precision`.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum PrecisionSetting {
    /// bf16 where it pays on this CPU, fp32 elsewhere.
    #[default]
    Auto,
    /// fp32 everywhere.
    F32,
    /// bf16 for the trunk's dense layers, whatever the CPU.
    Bf16,
}

impl PrecisionSetting {
    /// The name in a config file: `auto`, `f32` or `bf16`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::F32 => "f32",
            Self::Bf16 => "bf16",
        }
    }
}

impl std::str::FromStr for PrecisionSetting {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Self::Auto),
            "f32" | "fp32" => Ok(Self::F32),
            "bf16" => Ok(Self::Bf16),
            other => Err(format!(
                "precision must be auto, f32 or bf16, got {other:?}"
            )),
        }
    }
}

/// `runtime.device`.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum DeviceSetting {
    /// CUDA device 0 where libtorch has CUDA and sees a GPU, else the CPU.
    #[default]
    Auto,
    /// The CPU.
    Cpu,
    /// CUDA device 0; an error at start where there is none.
    Cuda,
}

impl DeviceSetting {
    /// The name in a config file: `auto`, `cpu` or `cuda`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Cpu => "cpu",
            Self::Cuda => "cuda",
        }
    }
}

impl std::str::FromStr for DeviceSetting {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Self::Auto),
            "cpu" => Ok(Self::Cpu),
            "cuda" => Ok(Self::Cuda),
            other => Err(format!("device must be auto, cpu or cuda, got {other:?}")),
        }
    }
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self {
            worker_threads: 2,
            compute_threads: 0,
            torch_threads: 1,
            learner_torch_threads: 0,
            precision: PrecisionSetting::Auto,
            device: DeviceSetting::Auto,
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

    /// libtorch's intra-op threads for the learner's training thread, if
    /// set: `learner_torch_threads`, else [`RuntimeConfig::torch_threads`].
    pub fn learner_torch_threads(&self) -> Option<usize> {
        match self.learner_torch_threads {
            0 => self.torch_threads(),
            n => Some(n),
        }
    }

    /// Range and relation checks, each with its dotted key. Pure: whether
    /// `device` can be met is the learner's question at start (and
    /// `doctor`'s), not the configuration's.
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
        problems.check(
            self.learner_torch_threads <= 1024,
            "learner_torch_threads",
            format!(
                "must be at most 1024 (0 = as torch_threads), got {}",
                self.learner_torch_threads
            ),
        );
        problems.into_vec()
    }
}
