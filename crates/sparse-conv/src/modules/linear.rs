//! A linear layer applied to every voxel.

use burn::config::Config;
use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::Device;

use crate::SparseTensor;

/// Configuration of a [`SparseLinear`].
#[derive(Config, Debug)]
pub struct SparseLinearConfig {
    pub channels: [usize; 2],
    #[config(default = true)]
    pub bias: bool,
}

/// `y = x·W + b` per voxel (a detection head, a 1×1×1 shortcut), PyTorch's default init.
#[derive(Module, Debug)]
pub struct SparseLinear {
    pub inner: Linear,
}

impl SparseLinearConfig {
    pub fn init(&self, device: &Device) -> SparseLinear {
        let [d_in, d_out] = self.channels;
        SparseLinear { inner: LinearConfig::new(d_in, d_out).with_bias(self.bias).init(device) }
    }
}

impl SparseLinear {
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        let features = self.inner.forward(x.features());
        x.with_features(features)
    }
}
