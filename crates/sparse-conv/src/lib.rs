//! Sparse 3D convolution for Burn: voxel coordinates, kernel maps, a differentiable op with its
//! own backward on every backend, and the modules a sparse U-Net is built from.
//!
//! - [`geometry`]: batch-indexed voxel coordinates and their hash index, kernel maps
//!   (submanifold, down-sampling, transposed), the GPU's tile plans.
//! - [`kernels`]: the math once per target: `kernels::cpu` (general kernels over slices, the
//!   f32 register-tile ones for AVX-512 and AVX2, batch norm's passes, Adam's step) and the CubeCL
//!   kernels for GPUs.
//! - [`ops`]: the op and its companions as Burn backend extensions, each with its own backward:
//!   the convolution ([`sparse_conv`]), batch norm, conv + norm at inference, channel
//!   concatenation, a backward from a given output gradient ([`backward_from`]).
//! - [`optim`]: [`FusedAdam`], Adam with the parameter and both moments updated in one pass.
//! - [`options`]: [`KernelOptions`], the kernels' knobs, set by the application.
//! - [`tensor`]: [`SparseTensor`], features with coordinates and a shared map cache.
//! - [`modules`]: convolutions, batch norm, linear and U-Net blocks.
//! - [`profile`]: the kernels' own time and operation counters.
//! - [`wgpu_device`]: the wgpu device on the platform's native graphics API (never OpenGL); an
//!   error in a build without the `wgpu` feature (CPU only).
//! - [`cuda_device`]: a CUDA GPU through Burn's CubeCL CUDA runtime, checked to run; an error in a
//!   build without the `cuda` feature.

#![warn(missing_docs)]

pub mod cuda_device;
pub mod geometry;
pub mod kernels;
pub mod modules;
pub mod ops;
pub mod optim;
pub mod options;
pub mod profile;
mod parallel;
pub mod tensor;
pub mod wgpu_device;

pub use ops::batch_norm::{BatchNormBackend, Epilogue, batch_norm_eval, batch_norm_train};
pub use ops::concat::{ChannelConcatBackend, concat_channels};
pub use ops::conv::{SparseConvBackend, sparse_conv};
pub use ops::conv_norm::{ConvNormBackend, sparse_conv_norm_eval};
pub use ops::output_grad::{OutputGradBackend, backward_from};
pub use optim::adam::{AdamBackend, FusedAdam, FusedAdamConfig};
pub use geometry::coords::{Coord, CoordError, CoordIndex};
pub use geometry::kernel_map::{KernelMap, MapKind, NeighborTable};
pub use geometry::level::LevelCoords;
pub use kernels::cpu::{cpu_features, cpu_kernel_path, cached_tile_gflops, fma_peak_gflops};
pub use options::{CpuKernels, GpuMaps, KernelOptions};
pub use tensor::{MapCache, SparseTensor};
pub use wgpu_device::wgpu_device;
pub use cuda_device::cuda_device;

pub use burn;
