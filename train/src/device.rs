//! Where the trainer's tensors live: the flex CPU backend (always built), or
//! a GPU through burn's wgpu backend pinned to Vulkan when the crate is built
//! with the opt-in `gpu` feature (`cargo build --release --features gpu`).
//! Vulkan, not CUDA: burn 0.22's CUDA backend downloads a prebuilt LLVM while
//! it builds, which an offline machine cannot; the Vulkan backend builds from
//! crates alone and runs on NVIDIA, AMD and Intel drivers. The Vulkan loader
//! is opened at run time, so a `gpu` build still starts on a machine without
//! one and fails only when a GPU is asked for.

use std::fmt;
use std::str::FromStr;

use burn::prelude::Device;

/// A training device as the command line names it: `cpu`, `gpu` or `gpu:N`
/// (the N-th discrete GPU).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TrainDevice {
    #[default]
    Cpu,
    /// The discrete GPU with this index.
    Gpu(usize),
}

/// Why a [`TrainDevice`] cannot be used.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum DeviceError {
    #[error("unknown training device {0:?}: use cpu, gpu or gpu:N")]
    Unknown(String),
    #[error(
        "this build of fusepose has no GPU backend, so it cannot train on {0}: rebuild with \
         `cargo build --release --features gpu` (needs a Vulkan driver and loader at run time), \
         or train on the cpu"
    )]
    NotBuilt(TrainDevice),
    #[error(
        "no GPU answered as {0} through Vulkan: install the Vulkan loader (libvulkan1) and the driver's \
         Vulkan ICD (`vulkaninfo --summary` should list the GPU); in a container NVIDIA's ICD also needs \
         libglvnd0, and VK_DRIVER_FILES may have to name its nvidia_icd.json"
    )]
    Unavailable(TrainDevice),
}

impl FromStr for TrainDevice {
    type Err = DeviceError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "cpu" => Ok(Self::Cpu),
            "gpu" => Ok(Self::Gpu(0)),
            _ => s
                .strip_prefix("gpu:")
                .and_then(|n| n.parse().ok())
                .map(Self::Gpu)
                .ok_or_else(|| DeviceError::Unknown(s.to_owned())),
        }
    }
}

impl fmt::Display for TrainDevice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Cpu => f.write_str("cpu"),
            Self::Gpu(n) => write!(f, "gpu:{n}"),
        }
    }
}

impl TrainDevice {
    /// Whether this build can train on GPUs at all.
    pub const GPU_BUILT: bool = cfg!(feature = "gpu");

    /// The burn device with autodiff, ready for a training loop. A GPU is
    /// first asked for one small computation, so that a missing driver is
    /// this error rather than a panic in the middle of training.
    pub fn autodiff(self) -> Result<Device, DeviceError> {
        let device = self.plain()?;
        if self != Self::Cpu && !answers(&device) {
            return Err(DeviceError::Unavailable(self));
        }
        Ok(device.autodiff())
    }

    /// The burn device without autodiff.
    pub fn plain(self) -> Result<Device, DeviceError> {
        match self {
            Self::Cpu => Ok(Device::flex()),
            #[cfg(feature = "gpu")]
            Self::Gpu(n) => Ok(Device::vulkan(burn::tensor::DeviceKind::DiscreteGpu(n))),
            #[cfg(not(feature = "gpu"))]
            Self::Gpu(_) => Err(DeviceError::NotBuilt(self)),
        }
    }
}

/// Whether `device` computes `2 × [1, 2]` (burn panics on a device thread
/// when it finds no adapter; the panic is caught here, and its message,
/// which the caller's error replaces, is not printed).
fn answers(device: &Device) -> bool {
    let device = device.clone();
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let ok = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
        let t = burn::prelude::Tensor::<1>::from_data(burn::prelude::TensorData::new(vec![1.0f32, 2.0], [2]), &device);
        (t * 2.0).into_data().try_to_vec::<f32>().is_ok_and(|v| v == [2.0, 4.0])
    }))
    .unwrap_or(false);
    std::panic::set_hook(hook);
    ok
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_print_back() {
        for (name, device) in
            [("cpu", TrainDevice::Cpu), ("gpu:0", TrainDevice::Gpu(0)), ("gpu:3", TrainDevice::Gpu(3))]
        {
            assert_eq!(name.parse::<TrainDevice>(), Ok(device));
            assert_eq!(device.to_string(), name);
        }
        assert_eq!("gpu".parse::<TrainDevice>(), Ok(TrainDevice::Gpu(0)));
        for bad in ["cuda", "gpu:", "gpu:x", "CPU"] {
            let err = bad.parse::<TrainDevice>().unwrap_err();
            assert!(err.to_string().contains("use cpu, gpu or gpu:N"), "{bad}: {err}");
        }
    }

    #[test]
    fn the_cpu_always_works_and_a_gpu_says_how_to_get_it_when_not_built() {
        assert!(TrainDevice::Cpu.autodiff().is_ok());
        assert!(answers(&TrainDevice::Cpu.plain().unwrap()));
        if !TrainDevice::GPU_BUILT {
            let err = TrainDevice::Gpu(0).autodiff().unwrap_err();
            assert_eq!(err, DeviceError::NotBuilt(TrainDevice::Gpu(0)));
            assert!(err.to_string().contains("--features gpu"), "{err}");
        }
    }
}
