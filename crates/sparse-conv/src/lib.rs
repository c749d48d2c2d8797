//! Sparse 3D convolution for Burn: voxel coordinates, kernel maps, a differentiable op with its
//! own backward on every backend, and the modules a sparse U-Net is built from.
//!
//! - [`geometry`]: batch-indexed voxel coordinates and their hash index, kernel maps
//!   (submanifold, down-sampling, transposed), the GPU's tile plans.
//! - [`kernels`]: the math once per target: `kernels::cpu` (general kernels over slices, the
//!   f32 register-tile ones for AVX-512 and AVX2, batch norm's passes, Adam's step) and the CubeCL
//!   kernels for GPUs.
//! - [`backend`]: the Burn backend extension and its `Autodiff` backward.
//! - [`batch_norm`]: batch norm (+ ReLU, + a residual's sum) as one op with its own backward.
//! - [`adam`]: Adam with the parameter and both moments updated in one pass per parameter.
//! - [`concat`]: channel concatenation (skip connections) as one op with its own backward.
//! - [`conv_norm`]: a conv and the batch norm after it at inference (fixed statistics, with
//!   its ReLU or a residual) as one op.
//! - [`op`]: [`sparse_conv`] on Burn tensors.
//! - [`options`]: [`KernelOptions`], the kernels' knobs, set by the application.
//! - [`output_grad`]: a backward pass from a given output gradient ([`backward_from`]).
//! - [`tensor`]: [`SparseTensor`], features with coordinates and a shared map cache.
//! - [`modules`]: convolutions, batch norm, linear and U-Net blocks.
//! - [`profile`]: the kernels' own time and operation counters.
//! - [`wgpu_device`]: the wgpu device on the platform's native graphics API (never OpenGL).

#![warn(missing_docs)]

pub mod adam;
pub mod backend;
pub mod batch_norm;
pub mod concat;
pub mod conv_norm;
pub mod geometry;
mod host;
pub mod kernels;
pub mod modules;
pub mod op;
pub mod options;
pub mod output_grad;
pub mod profile;
mod parallel;
pub mod tensor;
pub mod wgpu_device;

pub use backend::SparseConvBackend;
pub use adam::{AdamBackend, FusedAdam, FusedAdamConfig};
pub use batch_norm::{BatchNormBackend, Epilogue, batch_norm_eval, batch_norm_train};
pub use concat::{ChannelConcatBackend, concat_channels};
pub use conv_norm::{ConvNormBackend, sparse_conv_norm_eval};
pub use geometry::coords::{Coord, CoordError, CoordIndex};
pub use geometry::kernel_map::{KernelMap, MapKind, NeighborTable};
pub use op::sparse_conv;
pub use options::{CpuKernels, KernelOptions, cpu_features, cpu_kernel_path};
pub use output_grad::{OutputGradBackend, backward_from};
pub use tensor::{MapCache, SparseTensor};
pub use wgpu_device::wgpu_device;

pub use burn;
