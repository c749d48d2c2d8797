//! The blocks of a sparse U-Net (SPVNAS MinkUNet, its `core/models/semantic_kitti/minkunet.py`).

use burn::config::Config;
use burn::module::Module;
use burn::tensor::Device;

use super::{
    SparseBatchNorm, SparseBatchNormConfig, SparseConv3d, SparseConv3dConfig, SparseConvTranspose3d,
    SparseConvTranspose3dConfig, SubmanifoldConv3d, SubmanifoldConv3dConfig,
};
use crate::SparseTensor;
use crate::ops::batch_norm::Epilogue;

/// Configuration of a [`ConvBnRelu`].
#[derive(Config, Debug)]
pub struct ConvBnReluConfig {
    /// Input and output channels.
    pub channels: [usize; 2],
    #[config(default = 2)]
    /// Kernel size.
    pub kernel_size: usize,
}

/// Down-sampling conv (kernel = stride) → BN → ReLU: `BasicConvolutionBlock(k=2, s=2)`.
#[derive(Module, Debug)]
pub struct ConvBnRelu {
    /// The strided convolution.
    pub conv: SparseConv3d,
    /// Its batch norm.
    pub norm: SparseBatchNorm,
}

impl ConvBnReluConfig {
    /// A module with fresh parameters on `device`.
    pub fn init(&self, device: &Device) -> ConvBnRelu {
        ConvBnRelu {
            conv: SparseConv3dConfig::new(self.channels).with_kernel_size(self.kernel_size).init(device),
            norm: SparseBatchNormConfig::new(self.channels[1]).init(device),
        }
    }
}

impl ConvBnRelu {
    /// Applies the module to `x`'s features, on `x`'s coordinates (or the level it maps to).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        self.conv.forward_norm(x, &self.norm, Epilogue::Relu)
    }
}

/// Configuration of a [`DeconvBnRelu`].
#[derive(Config, Debug)]
pub struct DeconvBnReluConfig {
    /// Input and output channels.
    pub channels: [usize; 2],
    #[config(default = 2)]
    /// Kernel size.
    pub kernel_size: usize,
}

/// Transposed conv → BN → ReLU: `BasicDeconvolutionBlock(k=2, s=2)`.
#[derive(Module, Debug)]
pub struct DeconvBnRelu {
    /// The transposed convolution.
    pub conv: SparseConvTranspose3d,
    /// Its batch norm.
    pub norm: SparseBatchNorm,
}

impl DeconvBnReluConfig {
    /// A module with fresh parameters on `device`.
    pub fn init(&self, device: &Device) -> DeconvBnRelu {
        DeconvBnRelu {
            conv: SparseConvTranspose3dConfig::new(self.channels).with_kernel_size(self.kernel_size).init(device),
            norm: SparseBatchNormConfig::new(self.channels[1]).init(device),
        }
    }
}

impl DeconvBnRelu {
    /// Applies the module to `x`'s features, on `x`'s coordinates (or the level it maps to).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        self.conv.forward_norm(x, &self.norm, Epilogue::Relu)
    }
}

/// Configuration of a [`ResidualBlock`].
#[derive(Config, Debug)]
pub struct ResidualBlockConfig {
    /// Input and output channels.
    pub channels: [usize; 2],
    #[config(default = 3)]
    /// Kernel size.
    pub kernel_size: usize,
}

/// `relu([conv → BN → ReLU → conv → BN](x) + shortcut(x))`; the shortcut is the identity when
/// the channels match, else a 1×1×1 conv → BN.
#[derive(Module, Debug)]
pub struct ResidualBlock {
    /// First 3×3×3 convolution.
    pub conv1: SubmanifoldConv3d,
    /// Its batch norm.
    pub norm1: SparseBatchNorm,
    /// Second 3×3×3 convolution.
    pub conv2: SubmanifoldConv3d,
    /// Its batch norm (the ReLU follows the sum).
    pub norm2: SparseBatchNorm,
    /// 1×1 convolution and batch norm when the channels change; identity otherwise.
    pub shortcut: Option<Shortcut>,
}

/// The projection shortcut of a [`ResidualBlock`] whose channels change: 1×1×1 conv → BN.
#[derive(Module, Debug)]
pub struct Shortcut {
    /// The 1×1×1 convolution.
    pub conv: SubmanifoldConv3d,
    /// Its batch norm.
    pub norm: SparseBatchNorm,
}

impl ResidualBlockConfig {
    /// A module with fresh parameters on `device`.
    pub fn init(&self, device: &Device) -> ResidualBlock {
        let [c_in, c_out] = self.channels;
        let k = self.kernel_size;
        ResidualBlock {
            conv1: SubmanifoldConv3dConfig::new([c_in, c_out]).with_kernel_size(k).init(device),
            norm1: SparseBatchNormConfig::new(c_out).init(device),
            conv2: SubmanifoldConv3dConfig::new([c_out, c_out]).with_kernel_size(k).init(device),
            norm2: SparseBatchNormConfig::new(c_out).init(device),
            shortcut: (c_in != c_out).then(|| Shortcut {
                conv: SubmanifoldConv3dConfig::new([c_in, c_out]).with_kernel_size(1).init(device),
                norm: SparseBatchNormConfig::new(c_out).init(device),
            }),
        }
    }
}

impl ResidualBlock {
    /// Applies the module to `x`'s features, on `x`'s coordinates (or the level it maps to).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        let main = self.conv1.forward_norm(x.clone(), &self.norm1, Epilogue::Relu);
        let skip = match &self.shortcut {
            Some(shortcut) => shortcut.conv.forward_norm(x, &shortcut.norm, Epilogue::Identity),
            None => x,
        };
        self.conv2.forward_norm(main, &self.norm2, Epilogue::AddRelu(skip.into_features()))
    }
}
