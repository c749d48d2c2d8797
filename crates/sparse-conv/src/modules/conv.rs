//! The three sparse convolutions: submanifold, strided down-sampling, transposed up-sampling.

use std::sync::Arc;

use burn::config::Config;
use burn::module::{Module, Param};
use burn::nn::Initializer;
use burn::tensor::{Device, Tensor};

use super::SparseBatchNorm;
use super::turns::TiedKernel;
use crate::SparseTensor;
use crate::ops::batch_norm::Epilogue;
use crate::geometry::kernel_map::KernelMap;
use crate::ops::conv::sparse_conv;

/// `U(±bound)` for a `[K, C_in, C_out]` weight.
fn uniform_weight(volume: usize, c_in: usize, c_out: usize, bound: f64, device: &Device) -> Param<Tensor<3>> {
    Initializer::Uniform { min: -bound, max: bound }.init([volume, c_in, c_out], device)
}

/// Free weights `U(±bound)` for `tied`, which must build a `[volume, c_in, c_out]` kernel.
fn tied_weight(tied: &TiedKernel, volume: usize, c_in: usize, c_out: usize, bound: f64, device: &Device) -> Param<Tensor<3>> {
    assert_eq!(tied.full_shape(), [volume, c_in, c_out], "tied kernel of another shape than the convolution's");
    let [k, i, o] = tied.free_shape();
    uniform_weight(k, i, o, bound, device)
}

/// `weight` written out as the full weights `tied` builds from it (no tie left).
fn untied_weight(weight: Param<Tensor<3>>, tied: Option<Arc<TiedKernel>>) -> Param<Tensor<3>> {
    match tied {
        Some(tied) => Param::from_tensor(tied.expand(weight.val())),
        None => weight,
    }
}

/// The weights a convolution runs with: its own, or those `tied` builds from them.
fn full_weight(weight: &Param<Tensor<3>>, tied: &Option<Arc<TiedKernel>>) -> Tensor<3> {
    match tied {
        Some(tied) => tied.expand(weight.val()),
        None => weight.val(),
    }
}

/// Configuration of a [`SubmanifoldConv3d`].
#[derive(Config, Debug)]
pub struct SubmanifoldConv3dConfig {
    /// Input and output channels.
    pub channels: [usize; 2],
    /// Odd kernel size (3 in the network; 1 is a per-voxel matmul).
    #[config(default = 3)]
    pub kernel_size: usize,
}

/// Submanifold convolution: outputs on the input voxels, neighbours `{−r..r}³·stride`, no bias.
#[derive(Module, Debug)]
pub struct SubmanifoldConv3d {
    /// `[K, C_in, C_out]`, offsets x-major (see [`crate::KernelMap::submanifold`]).
    pub weight: Param<Tensor<3>>,
    /// Kernel size.
    pub kernel_size: usize,
    /// Ties `weight` across quarter turns: `weight` holds the free weights.
    #[module(skip)]
    pub tied: Option<Arc<TiedKernel>>,
}

impl SubmanifoldConv3dConfig {
    /// Weights `U(±1/√(C_in·K))`, torchsparse 1.2's initialisation.
    pub fn init(&self, device: &Device) -> SubmanifoldConv3d {
        assert!(self.kernel_size % 2 == 1, "submanifold kernel size must be odd, got {}", self.kernel_size);
        let [c_in, c_out] = self.channels;
        let volume = self.kernel_size.pow(3);
        let bound = 1.0 / ((c_in * volume) as f64).sqrt();
        SubmanifoldConv3d { weight: uniform_weight(volume, c_in, c_out, bound, device), kernel_size: self.kernel_size, tied: None }
    }

    /// The same convolution with its weights tied by `tied` (the free weights drawn with the
    /// same bound).
    pub fn init_tied(&self, tied: TiedKernel, device: &Device) -> SubmanifoldConv3d {
        let [c_in, c_out] = self.channels;
        let volume = self.kernel_size.pow(3);
        let bound = 1.0 / ((c_in * volume) as f64).sqrt();
        let weight = tied_weight(&tied, volume, c_in, c_out, bound, device);
        SubmanifoldConv3d { weight, kernel_size: self.kernel_size, tied: Some(Arc::new(tied)) }
    }
}

/// The features of a conv's output from its input's features, weight and map: the op alone, or
/// the op and the batch norm after it.
type ConvOp<'a> = &'a dyn Fn(Tensor<2>, Tensor<3>, &Arc<KernelMap>) -> Tensor<2>;

/// `norm` with `epilogue` after the conv, as one op where [`SparseBatchNorm::after_conv`] can.
fn then_norm(norm: &SparseBatchNorm, epilogue: Epilogue) -> impl Fn(Tensor<2>, Tensor<3>, &Arc<KernelMap>) -> Tensor<2> + '_ {
    move |x, w, map| norm.after_conv(x, w, map, epilogue.clone())
}

impl SubmanifoldConv3d {
    /// The same convolution with its tied weights written out: plain weights computing the
    /// same function (for inference, where the tie only costs time).
    pub fn untied(self) -> Self {
        Self { weight: untied_weight(self.weight, self.tied), tied: None, ..self }
    }

    /// Applies the module to `x`'s features, on `x`'s coordinates (or the level it maps to).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        self.run(x, &|x, w, map| sparse_conv(x, w, map))
    }

    /// `norm(self.forward(x))` with `epilogue`, one op at inference.
    pub fn forward_norm(&self, x: SparseTensor, norm: &SparseBatchNorm, epilogue: Epilogue) -> SparseTensor {
        self.run(x, &then_norm(norm, epilogue))
    }

    fn run(&self, x: SparseTensor, op: ConvOp<'_>) -> SparseTensor {
        // A 1×1×1 kernel is a per-voxel matmul, but it still runs as the op (over a map of the
        // identity pairs, built in O(N)): the op's GEMM and weight-gradient kernels are several
        // times faster than the backends' matmul on these tall, thin products.
        let map = x.submanifold_map(self.kernel_size);
        let features = op(x.features(), full_weight(&self.weight, &self.tied), &map);
        x.with_features(features)
    }
}

/// Configuration of a [`SparseConv3d`].
#[derive(Config, Debug)]
pub struct SparseConv3dConfig {
    /// Input and output channels.
    pub channels: [usize; 2],
    /// Kernel size, equal to the stride (2 in the network).
    #[config(default = 2)]
    pub kernel_size: usize,
}

/// Strided down-sampling convolution (kernel = stride): each coarse voxel sums its children.
#[derive(Module, Debug)]
pub struct SparseConv3d {
    /// Weights `[K, C_in, C_out]`, one matrix per kernel offset.
    pub weight: Param<Tensor<3>>,
    /// Kernel size.
    pub kernel_size: usize,
    /// Ties `weight` across quarter turns: `weight` holds the free weights.
    #[module(skip)]
    pub tied: Option<Arc<TiedKernel>>,
}

impl SparseConv3dConfig {
    /// Weights `U(±1/√(C_in·K))` (torchsparse 1.2's initialisation).
    pub fn init(&self, device: &Device) -> SparseConv3d {
        let [c_in, c_out] = self.channels;
        let volume = self.kernel_size.pow(3);
        let bound = 1.0 / ((c_in * volume) as f64).sqrt();
        SparseConv3d { weight: uniform_weight(volume, c_in, c_out, bound, device), kernel_size: self.kernel_size, tied: None }
    }

    /// The same convolution with its weights tied by `tied` (the free weights drawn with the
    /// same bound).
    pub fn init_tied(&self, tied: TiedKernel, device: &Device) -> SparseConv3d {
        let [c_in, c_out] = self.channels;
        let volume = self.kernel_size.pow(3);
        let bound = 1.0 / ((c_in * volume) as f64).sqrt();
        let weight = tied_weight(&tied, volume, c_in, c_out, bound, device);
        SparseConv3d { weight, kernel_size: self.kernel_size, tied: Some(Arc::new(tied)) }
    }
}

impl SparseConv3d {
    /// The same convolution with its tied weights written out: plain weights computing the
    /// same function (for inference, where the tie only costs time).
    pub fn untied(self) -> Self {
        Self { weight: untied_weight(self.weight, self.tied), tied: None, ..self }
    }

    /// Applies the module to `x`'s features, on `x`'s coordinates (or the level it maps to).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        self.run(x, &|x, w, map| sparse_conv(x, w, map))
    }

    /// `norm(self.forward(x))` with `epilogue`, one op at inference.
    pub fn forward_norm(&self, x: SparseTensor, norm: &SparseBatchNorm, epilogue: Epilogue) -> SparseTensor {
        self.run(x, &then_norm(norm, epilogue))
    }

    fn run(&self, x: SparseTensor, op: ConvOp<'_>) -> SparseTensor {
        let (map, coords) = x.down_map(self.kernel_size);
        let features = op(x.features(), full_weight(&self.weight, &self.tied), &map);
        x.on_level(features, coords, x.stride() * self.kernel_size as i32)
    }
}

/// Configuration of a [`SparseConvTranspose3d`].
#[derive(Config, Debug)]
pub struct SparseConvTranspose3dConfig {
    /// Input and output channels.
    pub channels: [usize; 2],
    #[config(default = 2)]
    /// Kernel size.
    pub kernel_size: usize,
}

/// Transposed convolution that reuses the down-sampling map of the same forward pass, so its
/// outputs land exactly on the finer level's voxels (as torchsparse 1.2 does).
#[derive(Module, Debug)]
pub struct SparseConvTranspose3d {
    /// Weights `[K, C_in, C_out]`, one matrix per kernel offset.
    pub weight: Param<Tensor<3>>,
    /// Kernel size.
    pub kernel_size: usize,
    /// Ties `weight` across quarter turns: `weight` holds the free weights.
    #[module(skip)]
    pub tied: Option<Arc<TiedKernel>>,
}

impl SparseConvTranspose3dConfig {
    /// Weights `U(±1/√C_out)`: torchsparse 1.2's operator-precedence quirk, as the authors have it.
    pub fn init(&self, device: &Device) -> SparseConvTranspose3d {
        let [c_in, c_out] = self.channels;
        let volume = self.kernel_size.pow(3);
        let bound = 1.0 / (c_out as f64).sqrt();
        SparseConvTranspose3d { weight: uniform_weight(volume, c_in, c_out, bound, device), kernel_size: self.kernel_size, tied: None }
    }

    /// The same convolution with its weights tied by `tied` (the free weights drawn with the
    /// same bound).
    pub fn init_tied(&self, tied: TiedKernel, device: &Device) -> SparseConvTranspose3d {
        let [c_in, c_out] = self.channels;
        let volume = self.kernel_size.pow(3);
        let bound = 1.0 / (c_out as f64).sqrt();
        let weight = tied_weight(&tied, volume, c_in, c_out, bound, device);
        SparseConvTranspose3d { weight, kernel_size: self.kernel_size, tied: Some(Arc::new(tied)) }
    }
}

impl SparseConvTranspose3d {
    /// The same convolution with its tied weights written out: plain weights computing the
    /// same function (for inference, where the tie only costs time).
    pub fn untied(self) -> Self {
        Self { weight: untied_weight(self.weight, self.tied), tied: None, ..self }
    }

    /// Applies the module to `x`'s features, on `x`'s coordinates (or the level it maps to).
    pub fn forward(&self, x: SparseTensor) -> SparseTensor {
        self.run(x, &|x, w, map| sparse_conv(x, w, map))
    }

    /// `norm(self.forward(x))` with `epilogue`, one op at inference.
    pub fn forward_norm(&self, x: SparseTensor, norm: &SparseBatchNorm, epilogue: Epilogue) -> SparseTensor {
        self.run(x, &then_norm(norm, epilogue))
    }

    fn run(&self, x: SparseTensor, op: ConvOp<'_>) -> SparseTensor {
        let (map, coords, fine) = x.up_map(self.kernel_size);
        let features = op(x.features(), full_weight(&self.weight, &self.tied), &map);
        x.on_level(features, coords, fine)
    }
}
