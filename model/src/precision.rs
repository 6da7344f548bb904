//! [`Precision`]: the number format a network computes its trunk in, and
//! the run-time choice behind `runtime.precision = "auto"`.
//!
//! Variables, weights files and optimizer state are f32 in either format.
//! `auto` picks bf16 only for training a conv trunk on a CPU with AMX-BF16
//! ([`Precision::choose`]); on a CUDA device `auto` is fp32
//! ([`Precision::choose_on`]).

use crossroads_config::PrecisionSetting;
use tch::Device;

use crate::spec::{NetworkSpec, TrunkKind};

/// The number format of a network's trunk. Variables always stay fp32 (the
/// master weights the optimizer updates and the files hold); in
/// [`Precision::Bf16`] the trunk's convolutions and dense layers cast their
/// input and weights to bf16 on the way in, so the gradients arrive in
/// fp32 through the casts. An MLP's sparse first layer stays fp32 (a
/// gather of a few dozen rows, nothing for a matrix unit to do), as do the
/// small value and advantage heads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    /// fp32 throughout.
    #[default]
    F32,
    /// bf16 for the trunk's heavy layers.
    Bf16,
}

/// What a network is run for, which decides what `auto` picks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Work {
    /// The learner's updates: forward, backward and the targets' forward
    /// passes at the training batch.
    Training,
    /// Inference only (actors, evaluation, rendering).
    Acting,
}

impl Precision {
    /// The format `setting` asks for a network of `spec` doing `work` on
    /// this CPU. `auto` is bf16 for training a conv trunk on a CPU with
    /// AMX-BF16, the one case measured faster, and fp32 for everything
    /// else: at an actor's small batches the casts of the weights cost
    /// what the matrix units save, an MLP has little dense work, and
    /// without matrix units bf16 is not measured to pay (figures:
    /// reports/performance/README.md, "bf16").
    pub fn choose(setting: PrecisionSetting, spec: &NetworkSpec, work: Work) -> Self {
        Self::choose_on(setting, spec, work, Device::Cpu)
    }

    /// [`Precision::choose`] for a network on `device`: on the CPU the
    /// same; elsewhere (a CUDA learner) `auto` is fp32, since the AMX
    /// measurement says nothing about a GPU and bf16 there is not
    /// measured, while an explicit `bf16` is kept.
    pub fn choose_on(
        setting: PrecisionSetting,
        spec: &NetworkSpec,
        work: Work,
        device: Device,
    ) -> Self {
        if device != Device::Cpu && setting == PrecisionSetting::Auto {
            return Self::F32;
        }
        match setting {
            PrecisionSetting::F32 => Self::F32,
            PrecisionSetting::Bf16 => Self::Bf16,
            PrecisionSetting::Auto => {
                if work == Work::Training && spec.trunk == TrunkKind::Conv && cpu_has_amx_bf16() {
                    Self::Bf16
                } else {
                    Self::F32
                }
            }
        }
    }

    /// `f32` or `bf16`.
    pub fn name(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::Bf16 => "bf16",
        }
    }
}

impl std::fmt::Display for Precision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Whether this CPU has AMX-BF16 tiles (CPUID leaf 7, EDX bit 22).
/// libtorch's oneDNN uses them for bf16 convolutions and matrix products
/// and falls back to AVX-512 where the kernel does not grant them.
pub fn cpu_has_amx_bf16() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let leaf = std::arch::x86_64::__cpuid(0);
        if leaf.eax < 7 {
            return false;
        }
        let features = std::arch::x86_64::__cpuid_count(7, 0);
        (features.edx >> 22) & 1 == 1
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
