//! The backend a benchmark binary runs on (`--backend`), and its device.

use clap::ValueEnum;
use serde::Serialize;
use sparse_conv::burn::tensor::Device;

/// The Burn backends the benchmarks compare.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// Burn's pure-Rust CPU backend.
    Flex,
    /// The ndarray CPU backend.
    Ndarray,
    /// wgpu on the platform's native graphics API.
    Wgpu,
    /// Burn's CubeCL CUDA runtime on the first GPU (a build with the `cuda` feature).
    Cuda,
}

impl Backend {
    /// The backend's device; a GPU backend without its device is an error saying what is missing.
    pub fn device(self) -> anyhow::Result<Device> {
        Ok(match self {
            Backend::Flex => Device::flex(),
            #[allow(deprecated)]
            Backend::Ndarray => Device::ndarray(),
            Backend::Wgpu => sparse_conv::wgpu_device().map_err(anyhow::Error::msg)?,
            Backend::Cuda => sparse_conv::cuda_device(0).map_err(anyhow::Error::msg)?,
        })
    }

    /// Its name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Flex => "flex",
            Backend::Ndarray => "ndarray",
            Backend::Wgpu => "wgpu",
            Backend::Cuda => "cuda",
        }
    }

    /// Whether it runs on the CPU (the slice kernels and the thread pool).
    pub fn is_cpu(self) -> bool {
        matches!(self, Backend::Flex | Backend::Ndarray)
    }
}
