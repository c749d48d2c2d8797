//! Burn modules over [`crate::SparseTensor`]s: the convolutions and what a sparse U-Net needs
//! around them.

mod blocks;
mod conv;
mod linear;
mod norm;
pub mod turns;

pub use blocks::{ConvBnRelu, ConvBnReluConfig, DeconvBnRelu, DeconvBnReluConfig, ResidualBlock, ResidualBlockConfig, Shortcut};
pub use conv::{
    SparseConv3d, SparseConv3dConfig, SparseConvTranspose3d, SparseConvTranspose3dConfig, SubmanifoldConv3d,
    SubmanifoldConv3dConfig,
};
pub use linear::{SparseLinear, SparseLinearConfig, per_voxel_linear, pooled_linear};
pub use norm::{SparseBatchNorm, SparseBatchNormConfig};

use crate::SparseTensor;

/// ReLU on the voxel features.
pub fn relu(x: SparseTensor) -> SparseTensor {
    x.map_features(burn::tensor::activation::relu)
}
