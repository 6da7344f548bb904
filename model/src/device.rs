//! The device `runtime.device` puts the learner's networks on
//! ([`resolve_device`]), and what this libtorch and machine offer for it
//! ([`CudaSupport`]).
//!
//! Only the learner asks: actors, evaluation and `doctor`'s forward passes
//! build their networks on the CPU ([`QNetwork::new`](crate::QNetwork::new)).

use crossroads_config::DeviceSetting;
use tch::Device;

use crate::ModelError;

/// What CUDA this process can use: whether the libtorch it links was built
/// with CUDA, how many CUDA devices that libtorch sees, and whether cuDNN
/// is usable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CudaSupport {
    /// libtorch has CUDA support (a CUDA build, its CUDA library loaded).
    pub built_with_cuda: bool,
    /// CUDA devices visible (0 without CUDA support).
    pub devices: i64,
    /// cuDNN is available.
    pub cudnn: bool,
}

impl CudaSupport {
    /// Asks libtorch. Safe on a CPU-only libtorch: it reports no CUDA,
    /// no devices and no cuDNN.
    pub fn probe() -> Self {
        let built_with_cuda = tch::utils::has_cuda();
        Self {
            built_with_cuda,
            devices: if built_with_cuda {
                tch::Cuda::device_count()
            } else {
                0
            },
            cudnn: built_with_cuda && tch::Cuda::cudnn_is_available(),
        }
    }

    /// Whether a network can go on CUDA device 0.
    pub fn available(&self) -> bool {
        self.built_with_cuda && self.devices > 0
    }

    /// The device `setting` asks for, given this support: `cpu` is the
    /// CPU; `auto` CUDA device 0 where [`CudaSupport::available`], else
    /// the CPU; `cuda` CUDA device 0, or an error naming what is missing
    /// (CUDA in libtorch, or a visible GPU).
    pub fn resolve(&self, setting: DeviceSetting) -> Result<Device, ModelError> {
        match setting {
            DeviceSetting::Cpu => Ok(Device::Cpu),
            DeviceSetting::Auto if self.available() => Ok(Device::Cuda(0)),
            DeviceSetting::Auto => Ok(Device::Cpu),
            DeviceSetting::Cuda if self.available() => Ok(Device::Cuda(0)),
            DeviceSetting::Cuda if !self.built_with_cuda => Err(ModelError::Device(
                "runtime.device = \"cuda\" but this libtorch was built without CUDA \
                 (a CPU build, such as scripts/setup-libtorch.sh assembles): build against \
                 a CUDA libtorch (docs/performance.md, \"A GPU learner\") or set \
                 runtime.device = \"cpu\""
                    .to_owned(),
            )),
            DeviceSetting::Cuda => Err(ModelError::Device(
                "runtime.device = \"cuda\" but libtorch has CUDA and sees no CUDA device \
                 (no GPU, no driver, or CUDA_VISIBLE_DEVICES hides it): make a GPU visible \
                 or set runtime.device = \"cpu\""
                    .to_owned(),
            )),
        }
    }
}

/// The device `setting` puts the learner's networks on, on this machine
/// ([`CudaSupport::resolve`] of [`CudaSupport::probe`]).
pub fn resolve_device(setting: DeviceSetting) -> Result<Device, ModelError> {
    CudaSupport::probe().resolve(setting)
}

/// A device as logs and `doctor` name it: `cpu`, `cuda:0`.
pub fn device_name(device: Device) -> String {
    match device {
        Device::Cpu => "cpu".to_owned(),
        Device::Cuda(i) => format!("cuda:{i}"),
        Device::Mps => "mps".to_owned(),
        Device::Vulkan => "vulkan".to_owned(),
    }
}
