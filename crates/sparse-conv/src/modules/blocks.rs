//! The blocks of a sparse U-Net (SPVNAS MinkUNet, its `core/models/semantic_kitti/minkunet.py`).

use burn::config::Config;
use burn::module::{Module, Param};
use burn::tensor::{Device, Int, Tensor, TensorData};

use super::turns::{TURNS, TiedKernel};
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
    #[config(default = false)]
    /// Channels hold four orientation copies and the weights are tied across quarter turns
    /// ([`super::turns`]); `channels` count every copy.
    pub turns: bool,
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
        let conv = SparseConv3dConfig::new(self.channels).with_kernel_size(self.kernel_size);
        ConvBnRelu {
            conv: match self.turns {
                true => conv.init_tied(regular(self.kernel_size, self.channels), device),
                false => conv.init(device),
            },
            norm: norm(self.channels[1], self.turns, device),
        }
    }
}

impl ConvBnRelu {
    /// Its ties written out ([`SparseConv3d::untied`], [`SparseBatchNorm::untied`]).
    pub fn untied(self) -> Self {
        Self { conv: self.conv.untied(), norm: self.norm.untied() }
    }

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
    #[config(default = false)]
    /// Channels hold four orientation copies and the weights are tied across quarter turns
    /// ([`super::turns`]); `channels` count every copy.
    pub turns: bool,
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
        let conv = SparseConvTranspose3dConfig::new(self.channels).with_kernel_size(self.kernel_size);
        DeconvBnRelu {
            conv: match self.turns {
                true => conv.init_tied(regular(self.kernel_size, self.channels), device),
                false => conv.init(device),
            },
            norm: norm(self.channels[1], self.turns, device),
        }
    }
}

impl DeconvBnRelu {
    /// Its ties written out ([`SparseConvTranspose3d::untied`], [`SparseBatchNorm::untied`]).
    pub fn untied(self) -> Self {
        Self { conv: self.conv.untied(), norm: self.norm.untied() }
    }

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
    #[config(default = false)]
    /// Channels hold four orientation copies and the weights are tied across quarter turns
    /// ([`super::turns`]); `channels` count every copy.
    pub turns: bool,
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
        let conv = |channels: [usize; 2], kernel: usize| {
            let config = SubmanifoldConv3dConfig::new(channels).with_kernel_size(kernel);
            match self.turns {
                true => config.init_tied(regular(kernel, channels), device),
                false => config.init(device),
            }
        };
        ResidualBlock {
            conv1: conv([c_in, c_out], k),
            norm1: norm(c_out, self.turns, device),
            conv2: conv([c_out, c_out], k),
            norm2: norm(c_out, self.turns, device),
            shortcut: (c_in != c_out).then(|| Shortcut { conv: conv([c_in, c_out], 1), norm: norm(c_out, self.turns, device) }),
        }
    }
}

impl ResidualBlock {
    /// Its ties written out ([`SubmanifoldConv3d::untied`], [`SparseBatchNorm::untied`]).
    pub fn untied(self) -> Self {
        Self {
            conv1: self.conv1.untied(),
            norm1: self.norm1.untied(),
            conv2: self.conv2.untied(),
            norm2: self.norm2.untied(),
            shortcut: self.shortcut.map(|s| Shortcut { conv: s.conv.untied(), norm: s.norm.untied() }),
        }
    }

    /// The same block fed its input channels in another order: input channel `i` is what
    /// channel `order[i]` was (the rows of the first convolution and of the shortcut reordered).
    pub fn with_input_order(mut self, order: &[usize]) -> Self {
        let reorder = |w: Param<Tensor<3>>| {
            let index: Vec<i64> = order.iter().map(|&i| i as i64).collect();
            let device = w.val().device();
            Param::from_tensor(w.val().select(1, Tensor::<1, Int>::from_data(TensorData::new(index, [order.len()]), &device)))
        };
        assert!(self.conv1.tied.is_none(), "reorder the input of an untied block");
        self.conv1.weight = reorder(self.conv1.weight);
        if let Some(shortcut) = &mut self.shortcut {
            shortcut.conv.weight = reorder(shortcut.conv.weight.clone());
        }
        self
    }

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

/// Weights tied across quarter turns between orientation copies of `channels / 4` each.
fn regular(kernel: usize, [c_in, c_out]: [usize; 2]) -> TiedKernel {
    assert!(c_in % TURNS == 0 && c_out % TURNS == 0, "channels {c_in} → {c_out} do not split into {TURNS} orientation copies");
    TiedKernel::regular(kernel, c_in / TURNS, c_out / TURNS)
}

/// Batch norm of `channels`, shared by the orientation copies when `turns`.
fn norm(channels: usize, turns: bool, device: &Device) -> SparseBatchNorm {
    SparseBatchNormConfig::new(channels).with_copies(if turns { TURNS } else { 1 }).init(device)
}
