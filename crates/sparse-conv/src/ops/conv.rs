//! The sparse convolution as a Burn backend extension, with its own backward in `Autodiff`.
//!
//! The CPU backends run the slice kernels of [`crate::kernels::cpu`], the cubecl backend (wgpu,
//! CUDA, …) the CubeCL kernels of `crate::kernels`. `Autodiff` registers a backward that calls the two gradient
//! methods of the inner backend, never a differentiated composition.
// burn-ndarray is deprecated in Burn 0.22 but is one of the CPU backends pmunet supports.
#![allow(deprecated)]

use std::sync::Arc;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::{FloatTensor, IndexingUpdateOp, IntTensor};
use burn::backend::{Autodiff, Backend, Dispatch, TensorMetadata, backend_extension};
#[cfg(feature = "cube")]
use burn_cubecl::CubeBackend;
use burn::tensor::{Shape, Tensor, TensorData};

use crate::kernels::cpu::{self, PairDirection};
use crate::kernels::cpu::norm as cpu_norm;
#[cfg(feature = "cube")]
use crate::kernels::cube;
use crate::geometry::kernel_map::KernelMap;
use crate::ops::host::{Host, HostFloats, on_host};
use crate::profile::{Kernel, count_conv_flops, in_kernel};

/// A backend that can run the sparse convolution of a [`KernelMap`].
///
/// Shapes: features `[n_in, C_in]`, weight `[K, C_in, C_out]`, output `[n_out, C_out]`.
///
/// The default bodies compose Burn primitives ([`composed`]); every backend pmunet runs on
/// overrides them with its own kernels. `Fusion` (wgpu's default) records the calls lazily and
/// runs the inner backend's kernels.
#[backend_extension(NdArray, Flex, Cube: cfg(feature = "cube"), Fusion: cfg(feature = "cube"), Autodiff)]
pub trait SparseConvBackend: Backend {
    /// `out[o] = Σ_k Σ_{(i, o) ∈ M_k} x[i] · W_k`.
    #[fusion(dtype = features, shape = Shape::new([map.n_out(), weight[2]]))]
    fn sparse_conv(features: FloatTensor<Self>, weight: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        composed::forward::<Self>(features, weight, &map)
    }

    /// The feature gradient: `dx[i] = Σ_k Σ_{(i, o) ∈ M_k} g[o] · W_kᵀ`.
    #[fusion(dtype = grad_out, shape = Shape::new([map.n_in(), weight[1]]))]
    fn sparse_conv_input_grad(grad_out: FloatTensor<Self>, weight: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        composed::input_grad::<Self>(grad_out, weight, &map)
    }

    /// The weight gradient: `dW_k = Σ_{(i, o) ∈ M_k} x[i]ᵀ · g[o]`, shape `[K, C_in, C_out]`.
    #[fusion(dtype = features, shape = Shape::new([map.volume(), features[1], grad_out[1]]))]
    fn sparse_conv_weight_grad(features: FloatTensor<Self>, grad_out: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        composed::weight_grad::<Self>(features, grad_out, &map)
    }
}

/// The op written with Burn primitives (select, matmul, select-assign per offset): the reference
/// any backend can run, and the fallback of the GPU kernels for dtypes they do not cover.
/// Differentiable, which is what a second derivative through `Autodiff` uses.
pub mod composed {
    use super::*;

    /// See [`SparseConvBackend::sparse_conv`].
    pub fn forward<B: Backend>(features: FloatTensor<B>, weight: FloatTensor<B>, map: &KernelMap) -> FloatTensor<B> {
        let n_out = map.n_out();
        let c_out = weight.shape()[2];
        let device = features.device();
        let mut out = B::float_zeros(Shape::new([n_out, c_out]), &device, features.dtype().into());
        for k in 0..map.volume() {
            let Some((input, output)) = offset_indices::<B>(map, k, &device) else { continue };
            let w_k = weight_slice::<B>(weight.clone(), k, &device);
            let gathered = B::float_select(features.clone(), 0, input);
            let product = B::float_matmul(gathered, w_k);
            out = B::float_select_assign(out, 0, output, product, IndexingUpdateOp::Add);
        }
        out
    }

    /// See [`SparseConvBackend::sparse_conv_input_grad`].
    pub fn input_grad<B: Backend>(grad_out: FloatTensor<B>, weight: FloatTensor<B>, map: &KernelMap) -> FloatTensor<B> {
        let c_in = weight.shape()[1];
        let device = grad_out.device();
        let mut grad = B::float_zeros(Shape::new([map.n_in(), c_in]), &device, grad_out.dtype().into());
        for k in 0..map.volume() {
            let Some((input, output)) = offset_indices::<B>(map, k, &device) else { continue };
            let w_k = B::float_transpose(weight_slice::<B>(weight.clone(), k, &device));
            let gathered = B::float_select(grad_out.clone(), 0, output);
            let product = B::float_matmul(gathered, w_k);
            grad = B::float_select_assign(grad, 0, input, product, IndexingUpdateOp::Add);
        }
        grad
    }

    /// See [`SparseConvBackend::sparse_conv_weight_grad`].
    pub fn weight_grad<B: Backend>(features: FloatTensor<B>, grad_out: FloatTensor<B>, map: &KernelMap) -> FloatTensor<B> {
        let c_in = features.shape()[1];
        let c_out = grad_out.shape()[1];
        let device = features.device();
        let dtype = features.dtype().into();
        let blocks = (0..map.volume())
            .map(|k| match offset_indices::<B>(map, k, &device) {
                None => B::float_zeros(Shape::new([1, c_in, c_out]), &device, dtype),
                Some((input, output)) => {
                    let xs = B::float_transpose(B::float_select(features.clone(), 0, input));
                    let gs = B::float_select(grad_out.clone(), 0, output);
                    B::float_reshape(B::float_matmul(xs, gs), Shape::new([1, c_in, c_out]))
                }
            })
            .collect();
        B::float_cat(blocks, 0)
    }
}

/// The input and output rows of offset `k` as index tensors, or `None` when it has no pairs.
fn offset_indices<B: Backend>(map: &KernelMap, k: usize, device: &burn::backend::tensor::Device<B>) -> Option<(IntTensor<B>, IntTensor<B>)> {
    let pairs = map.pairs();
    let (s, e) = (pairs.start[k], pairs.start[k + 1]);
    if s == e {
        return None;
    }
    let to_tensor = |rows: &[u32]| {
        let data: Vec<i32> = rows.iter().map(|&r| r as i32).collect();
        B::int_from_data(TensorData::new(data, [e - s]), device)
    };
    Some((to_tensor(&pairs.input[s..e]), to_tensor(&pairs.output[s..e])))
}

/// `W_k` as a `[C_in, C_out]` matrix.
fn weight_slice<B: Backend>(weight: FloatTensor<B>, k: usize, device: &burn::backend::tensor::Device<B>) -> FloatTensor<B> {
    let shape = weight.shape();
    let index = B::int_from_data(TensorData::new(vec![k as i32], [1]), device);
    B::float_reshape(B::float_select(weight, 0, index), Shape::new([shape[1], shape[2]]))
}

/// The batch norm with fixed statistics (and its ReLU or a residual's sum and ReLU) that a CPU
/// forward runs on its finished rows, as [`crate::kernels::cpu::norm::ConvEpilogue`] takes it.
pub(crate) struct NormAfterConv<B: Backend> {
    pub stats: FloatTensor<B>,
    pub gamma: FloatTensor<B>,
    pub beta: FloatTensor<B>,
    pub residual: Option<FloatTensor<B>>,
    pub epsilon: f64,
    pub relu: bool,
}

pub(crate) fn cpu_forward<B: HostFloats>(features: FloatTensor<B>, weight: FloatTensor<B>, map: &KernelMap, norm: Option<&NormAfterConv<B>>) -> FloatTensor<B> {
    let (c_in, c_out) = (weight.shape()[1], weight.shape()[2]);
    check_shapes(&features.shape(), &weight.shape(), map.n_in(), map.volume());
    count_conv_flops(map.pairs().input.len(), c_in, c_out);
    in_kernel(Kernel::ConvForward, || {
        on_host!(B, [features, weight], [map.n_out(), c_out], |T| {
            let norm_values = norm.map(|n| (T::host::<B>(&n.stats), T::host::<B>(&n.gamma), T::host::<B>(&n.beta), n.residual.as_ref().map(T::host::<B>)));
            let epilogue = norm.zip(norm_values.as_ref()).map(|(n, (stats, gamma, beta, residual))| {
                cpu_norm::ConvEpilogue::new(stats, gamma, beta, n.epsilon, n.relu, residual.as_deref())
            });
            let (x, w) = (T::host::<B>(&features), T::host::<B>(&weight));
            cpu::pair_conv(&x, c_in, &w, c_out, map.n_out(), PairDirection::Forward, map.pairs(), map.identity_offset(), epilogue.as_ref())
        })
    })
}

fn cpu_input_grad<B: HostFloats>(grad_out: FloatTensor<B>, weight: FloatTensor<B>, map: &KernelMap) -> FloatTensor<B> {
    let (c_in, c_out) = (weight.shape()[1], weight.shape()[2]);
    count_conv_flops(map.pairs().input.len(), c_in, c_out);
    in_kernel(Kernel::ConvInputGrad, || {
        on_host!(B, [grad_out, weight], [map.n_in(), c_in], |T| {
            cpu::pair_conv(&T::host::<B>(&grad_out), c_out, &T::host::<B>(&weight), c_in, map.n_in(), PairDirection::Backward, map.pairs_by_input(), map.identity_offset(), None)
        })
    })
}

fn cpu_weight_grad<B: HostFloats>(features: FloatTensor<B>, grad_out: FloatTensor<B>, map: &KernelMap) -> FloatTensor<B> {
    let (c_in, c_out) = (features.shape()[1], grad_out.shape()[1]);
    let pairs = map.pairs();
    count_conv_flops(pairs.input.len(), c_in, c_out);
    let out = in_kernel(Kernel::ConvWeightGrad, || {
        on_host!(B, [features, grad_out], [map.volume(), c_in * c_out], |T| {
            cpu::weight_grad(&T::host::<B>(&features), c_in, &T::host::<B>(&grad_out), c_out, pairs, map.identity_offset())
        })
    });
    B::float_reshape(out, Shape::new([map.volume(), c_in, c_out]))
}

fn check_shapes(features: &Shape, weight: &Shape, n_in: usize, volume: usize) {
    assert_eq!(features.num_dims(), 2, "sparse conv features must be [rows, channels], got {features:?}");
    assert_eq!(weight.num_dims(), 3, "sparse conv weight must be [K, C_in, C_out], got {weight:?}");
    assert_eq!(features[0], n_in, "features have {} rows but the kernel map expects {n_in}", features[0]);
    assert_eq!(weight[0], volume, "weight has {} offsets but the kernel map has {volume}", weight[0]);
    assert_eq!(features[1], weight[1], "features have {} channels, the weight expects {}", features[1], weight[1]);
}

/// The CPU kernels, on every backend that keeps its values on the host (flex, ndarray).
impl<B: HostFloats> SparseConvBackend for B {
    fn sparse_conv(features: FloatTensor<Self>, weight: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        cpu_forward::<Self>(features, weight, &map, None)
    }
    fn sparse_conv_input_grad(grad_out: FloatTensor<Self>, weight: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        cpu_input_grad::<Self>(grad_out, weight, &map)
    }
    fn sparse_conv_weight_grad(features: FloatTensor<Self>, grad_out: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        cpu_weight_grad::<Self>(features, grad_out, &map)
    }
}

/// CubeCL kernels for f32 ([`crate::kernels::cube`]), the composition for other dtypes.
#[cfg(feature = "cube")]
impl SparseConvBackend for CubeBackend {
    fn sparse_conv(features: FloatTensor<Self>, weight: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        check_shapes(&features.shape(), &weight.shape(), map.n_in(), map.volume());
        if cube::runs(&features) { cube::forward(features, weight, &map) } else { composed::forward::<Self>(features, weight, &map) }
    }
    fn sparse_conv_input_grad(grad_out: FloatTensor<Self>, weight: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        if cube::runs(&grad_out) { cube::input_grad(grad_out, weight, &map) } else { composed::input_grad::<Self>(grad_out, weight, &map) }
    }
    fn sparse_conv_weight_grad(features: FloatTensor<Self>, grad_out: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        if cube::runs(&features) { cube::weight_grad(features, grad_out, &map) } else { composed::weight_grad::<Self>(features, grad_out, &map) }
    }
}

#[derive(Debug)]
struct SparseConvBackward;

impl<B: SparseConvBackend> Backward<B, 2> for SparseConvBackward {
    type State = (FloatTensor<B>, FloatTensor<B>, Arc<KernelMap>);

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let [node_features, node_weight] = ops.parents;
        let grad = grads.consume::<B>(&ops.node);
        let (features, weight, map) = ops.state;
        if let Some(node) = node_weight {
            grads.register::<B>(node.id, B::sparse_conv_weight_grad(features, grad.clone(), map.clone()));
        }
        if let Some(node) = node_features {
            grads.register::<B>(node.id, B::sparse_conv_input_grad(grad, weight, map));
        }
    }
}

/// The gradient methods keep their default (composed, differentiable) bodies here, so a second
/// derivative still works; the first backward never calls them on `Autodiff`.
impl<B: SparseConvBackend, C: CheckpointStrategy> SparseConvBackend for Autodiff<B, C> {
    fn sparse_conv(features: FloatTensor<Self>, weight: FloatTensor<Self>, map: Arc<KernelMap>) -> FloatTensor<Self> {
        match SparseConvBackward.prepare::<C>([features.node(), weight.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let x = features.primitive().clone();
                let w = weight.primitive().clone();
                let out = B::sparse_conv(x.clone(), w.clone(), map.clone());
                prep.finish((x, w, map), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::sparse_conv(features.into_primitive(), weight.into_primitive(), map)),
        }
    }
}

/// `out[o] = Σ_k Σ_{(i, o) ∈ M_k} features[i] · weight[k]`, differentiable in both arguments.
///
/// `features` is `[map.n_in(), C_in]`, `weight` is `[map.volume(), C_in, C_out]`; the result is
/// `[map.n_out(), C_out]` on the same device.
pub fn sparse_conv(features: Tensor<2>, weight: Tensor<3>, map: &Arc<KernelMap>) -> Tensor<2> {
    check_conv_inputs(&features, &weight, map);
    Tensor::from_dispatch(<Dispatch as SparseConvBackend>::sparse_conv(
        features.into_dispatch(),
        weight.into_dispatch(),
        map.clone(),
    ))
}

/// Panics, naming the mismatch, unless `features` and `weight` fit `map` and each other; returns
/// the output channels.
pub(crate) fn check_conv_inputs(features: &Tensor<2>, weight: &Tensor<3>, map: &KernelMap) -> usize {
    let [rows, c_in] = features.dims();
    let [volume, w_in, c_out] = weight.dims();
    assert_eq!(rows, map.n_in(), "features have {rows} rows but the kernel map expects {}", map.n_in());
    assert_eq!(volume, map.volume(), "weight has {volume} offsets but the kernel map has {}", map.volume());
    assert_eq!(c_in, w_in, "features have {c_in} channels, the weight expects {w_in}");
    c_out
}
