//! The op's math, once per target: [`cpu`] (the general kernels over slices, and the AVX-512
//! and AVX2 ones for f32 where the CPU has them), `cube` (CubeCL kernels for GPUs: wgpu, CUDA,
//! ROCm). The kernels read their knobs from [`crate::options`]; the options know nothing of them.
//! Nothing here knows Burn's tensors; `crate::ops::conv` and the other ops call these.

pub mod cpu;
#[cfg(feature = "cube")]
pub(crate) mod cube;
