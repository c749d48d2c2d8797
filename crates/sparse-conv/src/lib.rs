//! Sparse 3D convolution for Burn: voxel coordinates, kernel maps, a differentiable op with its
//! own backward on every backend, and the modules a sparse U-Net is built from.
//!
//! - [`coords`]: batch-indexed voxel coordinates and their hash index.
//! - [`kernel_map`]: rulebooks for submanifold, down-sampling and transposed convolutions.
//! - [`cpu`]: the op's math over slices (forward, feature and weight gradients); `avx512`: the
//!   f32 micro-kernels of all three for CPUs with AVX-512.
//! - `cube`: the op's CubeCL kernels for GPUs (wgpu/Vulkan, CUDA, ROCm).
//! - [`backend`]: the Burn backend extension and its `Autodiff` backward.
//! - [`cpu_norm`], [`batch_norm`]: batch norm (+ ReLU, + a residual's sum) as one op with its
//!   own backward.
//! - [`adam`]: Adam with the parameter and both moments updated in one pass per parameter.
//! - [`concat`]: channel concatenation (skip connections) as one op with its own backward.
//! - [`conv_norm`]: a conv and the batch norm after it at inference (fixed statistics, with
//!   its ReLU or a residual) as one op.
//! - [`op`]: [`sparse_conv`] on Burn tensors.
//! - [`options`]: [`KernelOptions`], the kernels' knobs, set by the application.
//! - [`output_grad`]: a backward pass from a given output gradient ([`backward_from`]).
//! - [`tensor`]: [`SparseTensor`], features with coordinates and a shared map cache.
//! - [`modules`]: convolutions, batch norm, linear and U-Net blocks.
//! - [`scene`]: voxel scenes for benchmarks (a synthetic LiDAR-like scene, `.npy` files).
//! - [`heap`]: the binaries' malloc policy (freed tensor memory stays in the process).
//! - [`timing`]: medians and peak memory for the benchmark binaries.
//! - [`wgpu_device`]: the wgpu device on the platform's native graphics API (never OpenGL).

pub mod adam;
#[cfg(target_arch = "x86_64")]
mod avx512;
pub mod backend;
pub mod batch_norm;
pub mod concat;
pub mod conv_norm;
pub mod coords;
pub mod cpu;
pub mod cpu_norm;
mod cube;
pub mod heap;
pub mod kernel_map;
pub mod modules;
pub mod op;
pub mod options;
pub mod output_grad;
mod row_tiles;
pub mod scene;
pub mod tensor;
pub mod timing;
pub mod wgpu_device;

pub use backend::SparseConvBackend;
pub use adam::{AdamBackend, FusedAdam, FusedAdamConfig};
pub use batch_norm::{BatchNormBackend, Epilogue, batch_norm_eval, batch_norm_train};
pub use concat::{ChannelConcatBackend, concat_channels};
pub use conv_norm::{ConvNormBackend, sparse_conv_norm_eval};
pub use coords::{Coord, CoordError, CoordIndex};
pub use kernel_map::{KernelMap, MapKind, NeighborTable};
pub use op::sparse_conv;
pub use options::{CpuKernels, KernelOptions, cpu_features, cpu_kernel_path};
pub use output_grad::{OutputGradBackend, backward_from};
pub use tensor::{MapCache, SparseTensor};
pub use wgpu_device::wgpu_device;

pub use burn;
