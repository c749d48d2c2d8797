//! The wgpu device the op runs on: the platform's native graphics API, never OpenGL.
//!
//! `Device::wgpu` lets wgpu pick the graphics API, and on a Linux machine with Mesa's GL but no
//! Vulkan driver it settles on OpenGL (llvmpipe through EGL), where the op's CubeCL kernels wait
//! on a futex for ever. Pinning the API turns that machine's hang into an error that says what to
//! install.
//!
//! Without the crate's `wgpu` feature (a CPU-only build) there is no GPU backend and
//! [`wgpu_device`] is an error that says how to build one.

#[cfg(feature = "wgpu")]
use std::sync::OnceLock;

use burn::tensor::Device;
#[cfg(feature = "wgpu")]
use burn::tensor::wgpu::WgpuBackend;

/// The graphics APIs the op's CubeCL kernels are known to run on, in the order they are tried:
/// Metal on macOS, DX12 then Vulkan on Windows, Vulkan elsewhere.
#[cfg(feature = "wgpu")]
pub fn native_apis() -> &'static [WgpuBackend] {
    if cfg!(target_os = "macos") {
        &[WgpuBackend::Metal]
    } else if cfg!(target_os = "windows") {
        &[WgpuBackend::Dx12, WgpuBackend::Vulkan]
    } else {
        &[WgpuBackend::Vulkan]
    }
}

/// The default wgpu adapter on the first native API that has one, initialised once per process
/// (wgpu refuses to initialise the same device twice); an error naming what was tried otherwise.
#[cfg(feature = "wgpu")]
pub fn wgpu_device() -> Result<Device, String> {
    static DEVICE: OnceLock<Result<Device, String>> = OnceLock::new();
    DEVICE
        .get_or_init(|| {
            let mut failures = Vec::new();
            for &api in native_apis() {
                match Device::wgpu_options().graphics_api(api).init() {
                    Ok(device) => return Ok(device),
                    Err(e) => failures.push(format!("{api:?}: {e}")),
                }
            }
            Err(format!(
                "no wgpu adapter on {} ({}); OpenGL is not used, the op's kernels hang there. On Linux without a GPU, \
                 Mesa's software Vulkan driver works (Debian/Ubuntu: apt install mesa-vulkan-drivers libvulkan1), \
                 or choose a CPU backend (flex)",
                native_apis().iter().map(|a| format!("{a:?}")).collect::<Vec<_>>().join(" or "),
                failures.join("; ")
            ))
        })
        .clone()
}

/// A build without the `wgpu` feature has no GPU backend: an error saying how to get one.
#[cfg(not(feature = "wgpu"))]
pub fn wgpu_device() -> Result<Device, String> {
    Err("this build has no GPU backend: it was built with `--no-default-features`; build with the default \
         features (the `wgpu` feature) for `--backend wgpu`, or choose a CPU backend (flex)"
        .to_string())
}
