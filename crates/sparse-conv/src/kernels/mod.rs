//! The op's math, once per target: [`cpu`] (the general kernels over slices, and the AVX-512
//! ones for f32 where the CPU has them), `cube` (CubeCL kernels for GPUs: wgpu, CUDA, ROCm).
//! Nothing here knows Burn's tensors; `crate::ops::conv` and the other ops call these.

pub mod cpu;
pub(crate) mod cube;
