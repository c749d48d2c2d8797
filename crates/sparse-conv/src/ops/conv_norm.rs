//! A convolution and the batch norm after it, with fixed statistics (inference), as one op: with
//! the norm's ReLU, or a residual block's shortcut sum and ReLU.
//!
//! Why: with fixed statistics batch norm is a scale and a shift per channel. The CPU kernels
//! apply it (and the ReLU, and the residual) to each block of the conv's output rows while the
//! block is still in cache, instead of a pass over the features of its own. Other backends, and
//! `Autodiff` (where the result stays differentiable), run the conv and then the norm.
#![allow(deprecated)]

use std::sync::Arc;

use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Dispatch, backend_extension};
use burn::tensor::Tensor;
#[cfg(feature = "cube")]
use burn_cubecl::CubeBackend;

use crate::ops::host::HostFloats;
use crate::ops::conv::{NormAfterConv, SparseConvBackend, cpu_forward};
use crate::ops::batch_norm::{BatchNormBackend, Epilogue};
use crate::geometry::kernel_map::KernelMap;
use crate::ops::conv::check_conv_inputs;

/// A backend that runs a sparse convolution and the batch norm after it (fixed statistics) as
/// one op. Shapes as [`SparseConvBackend::sparse_conv`]'s; `stats` is `[2, C_out]` (mean, biased
/// variance), `gamma` and `beta` `[C_out]`.
#[backend_extension(NdArray, Flex, Cube: cfg(feature = "cube"), Fusion: cfg(feature = "cube"), Autodiff)]
pub trait ConvNormBackend: SparseConvBackend + BatchNormBackend {
    /// `relu?((conv(x) − mean)·γ/√(var + ε) + β)`.
    #[allow(clippy::too_many_arguments)]
    #[fusion(dtype = features, shape = burn::tensor::Shape::new([map.n_out(), weight[2]]))]
    fn sparse_conv_norm(
        features: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        map: Arc<KernelMap>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
    ) -> FloatTensor<Self> {
        Self::batch_norm_normalize(Self::sparse_conv(features, weight, map), stats, gamma, beta, epsilon, relu, false)
    }

    /// `relu((conv(x) − mean)·γ/√(var + ε) + β + residual)`.
    #[allow(clippy::too_many_arguments)]
    #[fusion(dtype = features, shape = burn::tensor::Shape::new([map.n_out(), weight[2]]))]
    fn sparse_conv_norm_add_relu(
        features: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        map: Arc<KernelMap>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        residual: FloatTensor<Self>,
        epsilon: f64,
    ) -> FloatTensor<Self> {
        Self::batch_norm_add_relu(Self::sparse_conv(features, weight, map), stats, gamma, beta, residual, epsilon, false)
    }
}

/// The CPU kernels, on every backend that keeps its values on the host (flex, ndarray).
impl<B: HostFloats> ConvNormBackend for B {
    fn sparse_conv_norm(
        features: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        map: Arc<KernelMap>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
    ) -> FloatTensor<Self> {
        let norm = NormAfterConv { stats, gamma, beta, residual: None, epsilon, relu };
        cpu_forward::<Self>(features, weight, &map, Some(&norm))
    }
    fn sparse_conv_norm_add_relu(
        features: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        map: Arc<KernelMap>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        residual: FloatTensor<Self>,
        epsilon: f64,
    ) -> FloatTensor<Self> {
        let norm = NormAfterConv { stats, gamma, beta, residual: Some(residual), epsilon, relu: true };
        cpu_forward::<Self>(features, weight, &map, Some(&norm))
    }
}

/// The conv's kernels, then the norm's (the trait's default bodies).
#[cfg(feature = "cube")]
impl ConvNormBackend for CubeBackend {}

/// The default bodies: the conv op and the norm op, each with its own backward.
impl<B: ConvNormBackend, C: CheckpointStrategy> ConvNormBackend for Autodiff<B, C> {}

/// `epilogue(batch_norm(sparse_conv(features, weight, map)))` with the statistics `mean`, `var`
/// (inference: the running averages): [`crate::batch_norm_eval`] of [`crate::sparse_conv`], in
/// one op where the backend has one.
#[allow(clippy::too_many_arguments)]
pub fn sparse_conv_norm_eval(
    features: Tensor<2>,
    weight: Tensor<3>,
    map: &Arc<KernelMap>,
    mean: Tensor<1>,
    var: Tensor<1>,
    gamma: Tensor<1>,
    beta: Tensor<1>,
    epsilon: f64,
    epilogue: Epilogue,
) -> Tensor<2> {
    let c_out = check_conv_inputs(&features, &weight, map);
    assert_eq!(gamma.dims()[0], c_out, "batch norm of {} channels after a conv of {c_out}", gamma.dims()[0]);
    let stats = Tensor::stack::<2>(vec![mean, var], 0).into_dispatch();
    let (x, w, map) = (features.into_dispatch(), weight.into_dispatch(), map.clone());
    let (gamma, beta) = (gamma.into_dispatch(), beta.into_dispatch());
    Tensor::from_dispatch(match epilogue {
        Epilogue::Identity => <Dispatch as ConvNormBackend>::sparse_conv_norm(x, w, map, stats, gamma, beta, epsilon, false),
        Epilogue::Relu => <Dispatch as ConvNormBackend>::sparse_conv_norm(x, w, map, stats, gamma, beta, epsilon, true),
        Epilogue::AddRelu(residual) => {
            assert_eq!(residual.dims(), [map.n_out(), c_out], "the residual must have the conv output's shape");
            <Dispatch as ConvNormBackend>::sparse_conv_norm_add_relu(x, w, map, stats, gamma, beta, residual.into_dispatch(), epsilon)
        }
    })
}
