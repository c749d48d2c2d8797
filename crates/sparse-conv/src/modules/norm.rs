//! Batch norm over voxel features.

use burn::config::Config;
use burn::module::Module;
use burn::nn::{BatchNorm, BatchNormConfig};
use burn::tensor::Device;

use crate::SparseTensor;

/// Configuration of a [`SparseBatchNorm`]; the defaults are PyTorch's `BatchNorm1d` (spec §1.6).
#[derive(Config, Debug)]
pub struct SparseBatchNormConfig {
    pub channels: usize,
    #[config(default = 1e-5)]
    pub epsilon: f64,
    #[config(default = 0.1)]
    pub momentum: f64,
}

/// Batch norm with every voxel of the batch as one sample: batch statistics and running-stat
/// updates on an autodiff device, running statistics otherwise (Burn's train/eval switch).
#[derive(Module, Debug)]
pub struct SparseBatchNorm {
    pub inner: BatchNorm,
}

impl SparseBatchNormConfig {
    /// Weight 1, bias 0.
    pub fn init(&self, device: &Device) -> SparseBatchNorm {
        let inner = BatchNormConfig::new(self.channels).with_epsilon(self.epsilon).with_momentum(self.momentum).init(device);
        SparseBatchNorm { inner }
    }
}

impl SparseBatchNorm {
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        let features = self.inner.forward(x.features());
        x.with_features(features)
    }
}
