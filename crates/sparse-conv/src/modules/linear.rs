//! A linear layer applied to every voxel.

use burn::config::Config;
use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::{Device, Tensor};

use super::turns::{FieldTurn, TiedKernel, pooled_bias};
use crate::{SparseTensor, sparse_conv};

/// Configuration of a [`SparseLinear`].
#[derive(Config, Debug)]
pub struct SparseLinearConfig {
    /// Input and output channels.
    pub channels: [usize; 2],
    #[config(default = true)]
    /// With a bias.
    pub bias: bool,
}

/// `y = x·W + b` per voxel (a detection head, a 1×1×1 shortcut), PyTorch's default init.
#[derive(Module, Debug)]
pub struct SparseLinear {
    /// Burn's linear layer, applied to every voxel's features.
    pub inner: Linear,
}

impl SparseLinearConfig {
    /// A module with fresh parameters on `device`.
    pub fn init(&self, device: &Device) -> SparseLinear {
        let [d_in, d_out] = self.channels;
        SparseLinear { inner: LinearConfig::new(d_in, d_out).with_bias(self.bias).init(device) }
    }
}

impl SparseLinear {
    /// Applies the module to `x`'s features, on `x`'s coordinates (or the level it maps to).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        let features = per_voxel_linear(&self.inner, &x);
        x.with_features(features)
    }
}

/// `linear` applied to the features of every voxel of `x`, `[N, d_out]`: the same as
/// `linear.forward(x.features())`, computed as a 1×1×1 sparse convolution (the op's GEMM and
/// weight-gradient kernels are several times faster than the backends' matmul on these tall,
/// thin products). Keeps Burn's `Linear` and its record.
pub fn per_voxel_linear(linear: &Linear, x: &SparseTensor) -> Tensor<2> {
    let [d_in, d_out] = linear.weight.dims();
    let map = x.submanifold_map(1);
    let out = sparse_conv(x.features(), linear.weight.val().reshape([1, d_in, d_out]), &map);
    match &linear.bias {
        Some(bias) => out + bias.val().unsqueeze_dim(0),
        None => out,
    }
}

/// `linear` (`[c, n]`) read from each of the four orientation copies of `x` (`4·c` channels,
/// orientation-major) and the four outputs averaged, each turned forward by its copy's turn as
/// `output` says: a head whose output turns with the cloud (`super::turns`). Only the part of
/// the bias that a turn leaves unchanged is added.
pub fn pooled_linear(linear: &Linear, x: &SparseTensor, output: &FieldTurn) -> Tensor<2> {
    let [c, n] = linear.weight.dims();
    let weight = TiedKernel::pooling(c, output).expand(linear.weight.val().reshape([1, c, n]));
    let out = sparse_conv(x.features(), weight, &x.submanifold_map(1));
    match &linear.bias {
        Some(bias) => out + pooled_bias(bias.val(), output).unsqueeze_dim(0),
        None => out,
    }
}
