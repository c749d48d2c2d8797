//! The CUDA device the op runs on: Burn's CubeCL CUDA runtime, running the same CubeCL kernels as
//! wgpu.
//!
//! The runtime loads the NVIDIA driver (`libcuda`) when the device is first used and panics where
//! there is none; [`cuda_device`] makes that first use itself, so a machine without a driver or
//! GPU gets an error naming what is missing instead of a panic in the middle of a run. Without
//! the crate's `cuda` feature it is an error that says how to build one.

use burn::tensor::Device;

/// CUDA GPU `index` (0 is the first), checked to run a kernel; an error naming what is missing
/// otherwise.
#[cfg(feature = "cuda")]
pub fn cuda_device(index: usize) -> Result<Device, String> {
    use burn::tensor::Tensor;
    use std::panic::{AssertUnwindSafe, catch_unwind};

    // The runtime's failure to find a driver or device is a panic; keep its message for the error
    // and out of the terminal.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let probe = catch_unwind(AssertUnwindSafe(|| {
        let device = Device::cuda(index);
        let sum: f32 = Tensor::<1>::ones([4], &device).sum().into_scalar();
        (device, sum)
    }));
    std::panic::set_hook(hook);
    match probe {
        Ok((device, sum)) if sum == 4.0 => Ok(device),
        Ok((_, sum)) => Err(format!("CUDA device {index} ran a test sum to {sum} instead of 4")),
        Err(panic) => {
            let reason = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "the CUDA runtime panicked".to_string());
            Err(format!(
                "no usable CUDA device {index} ({reason}); the CUDA backend needs an NVIDIA GPU and its driver (libcuda), \
                 not the toolkit. Choose wgpu or a CPU backend (flex) otherwise"
            ))
        }
    }
}

/// A build without the `cuda` feature has no CUDA backend: an error saying how to get one.
#[cfg(not(feature = "cuda"))]
pub fn cuda_device(index: usize) -> Result<Device, String> {
    let _ = index;
    Err("this build has no CUDA backend: build with `--features cuda` (it compiles without the CUDA toolkit), \
         or choose wgpu or a CPU backend (flex)"
        .to_string())
}
