//! The tensor backend, chosen at run time (`backend = "flex" | "ndarray" | "wgpu" | "cuda"`, `--backend`),
//! and the CPU thread count.

use anyhow::{Result, anyhow};
use burn::tensor::Device;
use serde::{Deserialize, Serialize};

/// Which Burn backend runs the numerics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum BackendKind {
    /// Burn's maintained pure-Rust CPU backend.
    #[default]
    Flex,
    /// The ndarray CPU backend (deprecated by Burn 0.22, kept for comparison).
    Ndarray,
    /// wgpu on the default adapter of the platform's native graphics API (Vulkan, Metal, DX12): a
    /// GPU, or Mesa's lavapipe on a CPU. Never OpenGL, where the op's kernels hang.
    Wgpu,
    /// CUDA on the first NVIDIA GPU, through Burn's CubeCL CUDA runtime (the same kernels as
    /// wgpu); in a build with the `cuda` feature.
    Cuda,
}

impl BackendKind {
    /// The plain (non-autodiff) device; `.autodiff()` of it trains. wgpu without an adapter on a
    /// native API, CUDA without a driver or without the build feature, are errors that say what to do.
    #[allow(deprecated)]
    pub fn device(self) -> Result<Device> {
        Ok(match self {
            BackendKind::Flex => Device::flex(),
            BackendKind::Ndarray => Device::ndarray(),
            BackendKind::Wgpu => sparse_conv::wgpu_device().map_err(|e| anyhow!("--backend wgpu: {e}"))?,
            BackendKind::Cuda => sparse_conv::cuda_device(0).map_err(|e| anyhow!("--backend cuda: {e}"))?,
        })
    }

    /// The plain device of index `index`: CUDA's GPUs by their index, the other backends' one
    /// device as 0 (several of them need `--backend cuda`).
    pub fn device_at(self, index: usize) -> Result<Device> {
        match (self, index) {
            (BackendKind::Cuda, i) => sparse_conv::cuda_device(i).map_err(|e| anyhow!("--backend cuda, device {i}: {e}")),
            (_, 0) => self.device(),
            (_, i) => Err(anyhow!("train.devices names device {i}, but --backend {} has one device (0); several GPUs need --backend cuda", self.name())),
        }
    }

    /// The name `BURN_DEVICE` knows it by.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Flex => "flex",
            BackendKind::Ndarray => "ndarray",
            BackendKind::Wgpu => "wgpu",
            BackendKind::Cuda => "cuda",
        }
    }

    /// Makes this backend Burn's default device for the process.
    ///
    /// Burn loads optimizer state onto `Device::default()` (which prefers wgpu whenever it is
    /// compiled in, adapter or not), so a resumed CPU run needs the default pinned to its own backend.
    ///
    /// # Safety
    /// Sets an environment variable: call it before any other thread exists (first thing in `main`).
    pub unsafe fn pin_default_device(self) {
        // SAFETY: the caller guarantees no other thread reads the environment concurrently.
        unsafe { std::env::set_var("BURN_DEVICE", self.name()) };
    }
}

/// Sizes the global thread pool the CPU kernels run on (`None`: one thread per core). Calling it
/// again with another size is an error; with the same size (or `None`) it is a no-op.
pub fn init_threads(threads: Option<usize>) -> Result<()> {
    let Some(n) = threads else { return Ok(()) };
    match rayon::ThreadPoolBuilder::new().num_threads(n).build_global() {
        Ok(()) => Ok(()),
        Err(_) if rayon::current_num_threads() == n => Ok(()),
        Err(e) => Err(anyhow!("cannot use {n} threads: the thread pool already has {} ({e})", rayon::current_num_threads())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--backend cuda` is an error that says what is missing where it cannot run (a build
    /// without the feature, a machine without a driver), never a panic; where it runs, it runs.
    #[test]
    fn cuda_is_a_device_or_an_error_saying_what_is_missing() {
        match BackendKind::Cuda.device() {
            Ok(device) => {
                assert!(cfg!(feature = "cuda"), "a build without the cuda feature made a CUDA device");
                let x = burn::tensor::Tensor::<1>::ones([3], &device).sum().into_scalar::<f32>();
                assert_eq!(x, 3.0);
            }
            Err(e) => {
                let e = e.to_string();
                let expected = if cfg!(feature = "cuda") { "no usable CUDA device" } else { "build with `--features cuda`" };
                assert!(e.starts_with("--backend cuda: ") && e.contains(expected), "{e}");
            }
        }
    }
}
