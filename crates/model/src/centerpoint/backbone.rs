//! The 2D BEV backbone (CenterPoint's `RPN`, `rpn.py`): down blocks of 3×3 convolutions, an up
//! block per down block, outputs concatenated at one resolution.

use sparse_conv::burn::module::Module;
use sparse_conv::burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use sparse_conv::burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use sparse_conv::burn::tensor::activation::relu;
use sparse_conv::burn::tensor::{Device, Tensor};

use super::config::CenterPointConfig;

/// Conv → BN (eps 1e-3) → ReLU, no conv bias.
#[derive(Module, Debug)]
pub struct ConvBnRelu2d {
    /// The convolution.
    pub conv: Conv2d,
    /// Its batch norm.
    pub norm: BatchNorm,
}

impl ConvBnRelu2d {
    /// A 3×3 convolution with padding 1 and the given stride.
    pub fn new(c_in: usize, c_out: usize, stride: usize, momentum: f64, device: &Device) -> Self {
        Self {
            conv: Conv2dConfig::new([c_in, c_out], [3, 3])
                .with_stride([stride, stride])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .with_bias(false)
                .init(device),
            norm: bn(c_out, momentum, device),
        }
    }

    /// `[B, C_in, X, Y] → [B, C_out, X/s, Y/s]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        relu(self.norm.forward(self.conv.forward(x)))
    }
}

/// Batch norm with CenterPoint's eps 1e-3 and the given momentum.
pub fn bn(c: usize, momentum: f64, device: &Device) -> BatchNorm {
    BatchNormConfig::new(c).with_epsilon(1e-3).with_momentum(momentum).init(device)
}

/// Transposed conv (kernel = stride) → BN → ReLU.
#[derive(Module, Debug)]
pub struct DeconvBnRelu2d {
    /// The transposed convolution, no bias.
    pub deconv: ConvTranspose2d,
    /// Its batch norm.
    pub norm: BatchNorm,
}

impl DeconvBnRelu2d {
    /// `[B, C_in, X, Y] → [B, C_out, X·s, Y·s]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        relu(self.norm.forward(self.deconv.forward(x)))
    }
}

/// Down blocks and up blocks; the output is `[up_1(x_1), up_2(x_2), …]` along channels.
#[derive(Module, Debug)]
pub struct BevBackbone {
    /// Down block i: a strided conv then `layer_nums[i]` convs.
    pub down: Vec<Vec<ConvBnRelu2d>>,
    /// Up block i, from down block i's output to the common resolution.
    pub up: Vec<DeconvBnRelu2d>,
}

impl BevBackbone {
    /// The backbone of `cfg` on `c_in` input channels.
    ///
    /// # Panics
    /// If the block lists differ in length or the blocks do not meet at one resolution.
    pub fn new(cfg: &CenterPointConfig, c_in: usize, device: &Device) -> Self {
        let n = cfg.layer_nums.len();
        assert!(
            n > 0 && [cfg.down_strides.len(), cfg.down_filters.len(), cfg.up_strides.len(), cfg.up_filters.len()].iter().all(|&l| l == n),
            "layer_nums, down_strides, down_filters, up_strides and up_filters need one entry per block"
        );
        let mut stride = 1;
        let out_stride = cfg.down_strides[0] / cfg.up_strides[0];
        let mut c = c_in;
        let (mut down, mut up) = (Vec::new(), Vec::new());
        for i in 0..n {
            stride *= cfg.down_strides[i];
            assert!(
                cfg.up_strides[i] > 0 && stride == out_stride * cfg.up_strides[i],
                "block {i} at stride {stride} with up factor {} does not land on output stride {out_stride}",
                cfg.up_strides[i]
            );
            let f = cfg.scaled(cfg.down_filters[i]);
            let mut block = vec![ConvBnRelu2d::new(c, f, cfg.down_strides[i], cfg.bn_momentum, device)];
            block.extend((0..cfg.layer_nums[i]).map(|_| ConvBnRelu2d::new(f, f, 1, cfg.bn_momentum, device)));
            down.push(block);
            let s = cfg.up_strides[i];
            let u = cfg.scaled(cfg.up_filters[i]);
            up.push(DeconvBnRelu2d {
                deconv: ConvTranspose2dConfig::new([f, u], [s, s]).with_stride([s, s]).with_bias(false).init(device),
                norm: bn(u, cfg.bn_momentum, device),
            });
            c = f;
        }
        Self { down, up }
    }

    /// Channels of the concatenated output.
    pub fn out_channels(&self) -> usize {
        self.up.iter().map(|u| u.deconv.weight.dims()[1]).sum()
    }

    /// `[B, C_in, X, Y] → [B, Σ up_filters, X/out_stride, Y/out_stride]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = x;
        let mut outs = Vec::with_capacity(self.up.len());
        for (block, up) in self.down.iter().zip(&self.up) {
            for layer in block {
                x = layer.forward(x);
            }
            outs.push(up.forward(x.clone()));
        }
        Tensor::cat(outs, 1)
    }
}
