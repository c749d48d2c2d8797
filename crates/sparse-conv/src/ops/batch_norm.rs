//! Batch norm over voxel features, optionally fused with the ReLU after it, as one Burn op with
//! its own backward.
//!
//! Why not Burn's `batch_norm_train`: on the CPU backends it is composed of primitives (transposed
//! copies of `[rows, C]` for each statistic, about a dozen passes forward and backward) and the
//! ReLU after it is two passes more; in a MinkUNet training step that was a quarter of the time.
//! Here the CPU backends run [`crate::kernels::cpu::norm`] (one pass per method); other backends compose
//! the same math ([`composed`]), which `Fusion` fuses on GPUs.
//!
//! Shapes: features `[rows, C]`, `gamma` and `beta` `[C]`, `stats` `[2, C]` (mean; biased
//! variance), the parameter gradients `[2, C]` (dγ; dβ).
#![allow(deprecated)]


use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::NodeId;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Scalar, TensorMetadata, backend_extension};
use burn::tensor::{Shape, Slice, Tensor};
#[cfg(feature = "cube")]
use burn_cubecl::CubeBackend;

use crate::ops::host::{Host, HostFloats, on_host};
use crate::kernels::cpu::norm as cpu_norm;
use crate::profile::{Kernel, in_kernel};

/// A backend that runs batch norm (+ ReLU) over `[rows, C]` features in a few passes.
///
/// `batch_stats` says the statistics are the features' own (training): the backward then
/// differentiates through them. `relu` applies `max(·, 0)` to the normalised features.
#[backend_extension(NdArray, Flex, Cube: cfg(feature = "cube"), Fusion: cfg(feature = "cube"), Autodiff)]
pub trait BatchNormBackend: Backend {
    /// Mean and biased variance per channel, `[2, C]`. A constant: not differentiated.
    #[fusion(dtype = x, shape = Shape::new([2, x[1]]))]
    fn batch_norm_stats(x: FloatTensor<Self>) -> FloatTensor<Self> {
        composed::stats::<Self>(x)
    }

    /// `relu?((x − mean)·γ/√(var + ε) + β)`.
    #[fusion(dtype = x, shape = x)]
    fn batch_norm_normalize(
        x: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
        batch_stats: bool,
    ) -> FloatTensor<Self> {
        let _ = batch_stats;
        composed::normalize::<Self>(x, stats, gamma, beta, epsilon, relu)
    }

    /// `relu((x − mean)·γ/√(var + ε) + β + residual)`: a residual block's last batch norm, its
    /// shortcut's sum and the ReLU in one pass, where composed they are three.
    #[allow(clippy::too_many_arguments)]
    #[fusion(dtype = x, shape = x)]
    fn batch_norm_add_relu(
        x: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        residual: FloatTensor<Self>,
        epsilon: f64,
        batch_stats: bool,
    ) -> FloatTensor<Self> {
        let _ = batch_stats;
        Self::relu(Self::float_add(composed::normalize::<Self>(x, stats, gamma, beta, epsilon, false), residual))
    }

    /// ReLU's backward from its output `y` (`grad_out` where `y > 0`, else 0): the first step
    /// of [`Self::batch_norm_add_relu`]'s backward, and the residual's gradient.
    #[fusion(dtype = grad_out, shape = grad_out)]
    fn batch_norm_relu_grad(y: FloatTensor<Self>, grad_out: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::relu_backward(y, grad_out)
    }

    /// `[dγ; dβ]` for the output gradient `grad_out`.
    #[fusion(dtype = x, shape = Shape::new([2, x[1]]))]
    fn batch_norm_param_grads(
        x: FloatTensor<Self>,
        grad_out: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
    ) -> FloatTensor<Self> {
        composed::param_grads::<Self>(x, grad_out, stats, gamma, beta, epsilon, relu)
    }

    /// The input gradient; `param_grads` is [`Self::batch_norm_param_grads`] of the same call.
    #[allow(clippy::too_many_arguments)]
    #[fusion(dtype = x, shape = x)]
    fn batch_norm_input_grad(
        x: FloatTensor<Self>,
        grad_out: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        param_grads: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
        batch_stats: bool,
    ) -> FloatTensor<Self> {
        composed::input_grad::<Self>(x, grad_out, stats, gamma, beta, param_grads, epsilon, relu, batch_stats)
    }
}

/// The layer composed of Burn primitives: what GPU backends run (fused there by `Fusion`), and
/// the reference the CPU passes are tested against. Same conventions as [`crate::kernels::cpu::norm`].
pub mod composed {
    use super::*;

    fn row<B: Backend>(t: FloatTensor<B>, i: usize) -> FloatTensor<B> {
        let c = t.shape()[1];
        B::float_slice(t, &[Slice::from(i..i + 1), Slice::from(0..c)])
    }

    fn as_row<B: Backend>(t: FloatTensor<B>) -> FloatTensor<B> {
        let c = t.shape()[0];
        B::float_reshape(t, Shape::new([1, c]))
    }

    /// `(a, b, 1/√(var + ε))` as `[1, C]` rows: `z = x·a + b`.
    fn affine<B: Backend>(stats: FloatTensor<B>, gamma: FloatTensor<B>, beta: FloatTensor<B>, epsilon: f64) -> [FloatTensor<B>; 3] {
        let mean = row::<B>(stats.clone(), 0);
        let inv_std = B::float_recip(B::float_sqrt(B::float_add_scalar(row::<B>(stats, 1), Scalar::Float(epsilon))));
        let a = B::float_mul(as_row::<B>(gamma), inv_std.clone());
        let b = B::float_sub(as_row::<B>(beta), B::float_mul(mean, a.clone()));
        [a, b, inv_std]
    }

    fn z<B: Backend>(x: FloatTensor<B>, a: FloatTensor<B>, b: FloatTensor<B>) -> FloatTensor<B> {
        B::float_add(B::float_mul(x, a), b)
    }

    /// `grad_out` through the ReLU's mask (zero where `z ≤ 0`), or unchanged.
    fn masked<B: Backend>(z: FloatTensor<B>, grad_out: FloatTensor<B>, relu: bool) -> FloatTensor<B> {
        if relu { B::relu_backward(B::relu(z), grad_out) } else { grad_out }
    }

    /// See [`BatchNormBackend::batch_norm_stats`].
    pub fn stats<B: Backend>(x: FloatTensor<B>) -> FloatTensor<B> {
        let mean = B::float_mean_dim(x.clone(), 0);
        let centered = B::float_sub(x, mean.clone());
        let var = B::float_mean_dim(B::float_mul(centered.clone(), centered), 0);
        B::float_cat(vec![mean, var], 0)
    }

    /// See [`BatchNormBackend::batch_norm_normalize`].
    pub fn normalize<B: Backend>(
        x: FloatTensor<B>,
        stats: FloatTensor<B>,
        gamma: FloatTensor<B>,
        beta: FloatTensor<B>,
        epsilon: f64,
        relu: bool,
    ) -> FloatTensor<B> {
        let [a, b, _] = affine::<B>(stats, gamma, beta, epsilon);
        let z = z::<B>(x, a, b);
        if relu { B::relu(z) } else { z }
    }

    /// See [`BatchNormBackend::batch_norm_param_grads`].
    #[allow(clippy::too_many_arguments)]
    pub fn param_grads<B: Backend>(
        x: FloatTensor<B>,
        grad_out: FloatTensor<B>,
        stats: FloatTensor<B>,
        gamma: FloatTensor<B>,
        beta: FloatTensor<B>,
        epsilon: f64,
        relu: bool,
    ) -> FloatTensor<B> {
        let mean = row::<B>(stats.clone(), 0);
        let [a, b, inv_std] = affine::<B>(stats, gamma, beta, epsilon);
        let dz = masked::<B>(z::<B>(x.clone(), a, b), grad_out, relu);
        let x_hat = B::float_mul(B::float_sub(x, mean), inv_std);
        let dgamma = B::float_sum_dim(B::float_mul(dz.clone(), x_hat), 0);
        let dbeta = B::float_sum_dim(dz, 0);
        B::float_cat(vec![dgamma, dbeta], 0)
    }

    /// See [`BatchNormBackend::batch_norm_input_grad`].
    #[allow(clippy::too_many_arguments)]
    pub fn input_grad<B: Backend>(
        x: FloatTensor<B>,
        grad_out: FloatTensor<B>,
        stats: FloatTensor<B>,
        gamma: FloatTensor<B>,
        beta: FloatTensor<B>,
        param_grads: FloatTensor<B>,
        epsilon: f64,
        relu: bool,
        batch_stats: bool,
    ) -> FloatTensor<B> {
        let rows = x.shape()[0];
        let mean = row::<B>(stats.clone(), 0);
        let [a, b, inv_std] = affine::<B>(stats, gamma, beta, epsilon);
        let dz = masked::<B>(z::<B>(x.clone(), a.clone(), b), grad_out, relu);
        let direct = B::float_mul(dz, a.clone());
        if !batch_stats || rows == 0 {
            return direct;
        }
        // − a/N · (dβ + x̂·dγ)
        let x_hat = B::float_mul(B::float_sub(x, mean), inv_std);
        let through_stats = B::float_add(row::<B>(param_grads.clone(), 1), B::float_mul(x_hat, row::<B>(param_grads, 0)));
        let scale = B::float_mul_scalar(a, Scalar::Float(-1.0 / rows as f64));
        B::float_add(direct, B::float_mul(through_stats, scale))
    }
}

fn check(x: &Shape, c: usize, what: &str) {
    assert_eq!(x.num_dims(), 2, "batch norm features must be [rows, channels], got {x:?}");
    assert_eq!(x[1], c, "batch norm {what}: features have {} channels, the layer {c}", x[1]);
}

/// The CPU kernels, on every backend that keeps its values on the host (flex, ndarray).
impl<B: HostFloats> BatchNormBackend for B {
    fn batch_norm_stats(x: FloatTensor<Self>) -> FloatTensor<Self> {
        let shape = x.shape();
        assert_eq!(shape.num_dims(), 2, "batch norm features must be [rows, channels], got {shape:?}");
        let c = shape[1];
        in_kernel(Kernel::BatchNorm, || on_host!(Self, [x], [2, c], |T| cpu_norm::channel_stats(&T::host::<Self>(&x), c)))
    }
    fn batch_norm_normalize(
        x: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
        _batch_stats: bool,
    ) -> FloatTensor<Self> {
        let shape = x.shape();
        check(&shape, gamma.shape()[0], "forward");
        in_kernel(Kernel::BatchNorm, || on_host!(Self, [x, stats, gamma, beta], [shape[0], shape[1]], |T| cpu_norm::normalize(
            &T::host::<Self>(&x),
            &T::host::<Self>(&stats),
            &T::host::<Self>(&gamma),
            &T::host::<Self>(&beta),
            epsilon,
            relu
        )))
    }
    fn batch_norm_add_relu(
        x: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        residual: FloatTensor<Self>,
        epsilon: f64,
        _batch_stats: bool,
    ) -> FloatTensor<Self> {
        let shape = x.shape();
        check(&shape, gamma.shape()[0], "forward");
        assert_eq!(residual.shape(), shape, "batch norm residual must match the features");
        in_kernel(Kernel::BatchNorm, || on_host!(Self, [x, stats, gamma, beta, residual], [shape[0], shape[1]], |T| cpu_norm::normalize_add_relu(
            &T::host::<Self>(&x),
            &T::host::<Self>(&stats),
            &T::host::<Self>(&gamma),
            &T::host::<Self>(&beta),
            &T::host::<Self>(&residual),
            epsilon
        )))
    }
    fn batch_norm_relu_grad(y: FloatTensor<Self>, grad_out: FloatTensor<Self>) -> FloatTensor<Self> {
        let shape = y.shape();
        assert_eq!(grad_out.shape(), shape, "ReLU output and its gradient differ in shape");
        in_kernel(Kernel::BatchNorm, || on_host!(Self, [y, grad_out], shape.clone(), |T| cpu_norm::relu_grad(&T::host::<Self>(&y), &T::host::<Self>(&grad_out))))
    }
    fn batch_norm_param_grads(
        x: FloatTensor<Self>,
        grad_out: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
    ) -> FloatTensor<Self> {
        let c = gamma.shape()[0];
        check(&x.shape(), c, "backward");
        in_kernel(Kernel::BatchNorm, || on_host!(Self, [x, grad_out, stats, gamma, beta], [2, c], |T| cpu_norm::param_grads(
            &T::host::<Self>(&x),
            &T::host::<Self>(&grad_out),
            &T::host::<Self>(&stats),
            &T::host::<Self>(&gamma),
            &T::host::<Self>(&beta),
            epsilon,
            relu
        )))
    }
    fn batch_norm_input_grad(
        x: FloatTensor<Self>,
        grad_out: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        param_grads: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
        batch_stats: bool,
    ) -> FloatTensor<Self> {
        let shape = x.shape();
        check(&shape, gamma.shape()[0], "backward");
        in_kernel(Kernel::BatchNorm, || on_host!(Self, [x, grad_out, stats, gamma, beta, param_grads], [shape[0], shape[1]], |T| cpu_norm::input_grad(
            &T::host::<Self>(&x),
            &T::host::<Self>(&grad_out),
            &T::host::<Self>(&stats),
            &T::host::<Self>(&gamma),
            &T::host::<Self>(&beta),
            &T::host::<Self>(&param_grads),
            epsilon,
            relu,
            batch_stats
        )))
    }
}

/// The composition (the trait's default bodies).
#[cfg(feature = "cube")]
impl BatchNormBackend for CubeBackend {}

#[derive(Debug)]
struct BatchNormBackward;

impl<B: BatchNormBackend> Backward<B, 3> for BatchNormBackward {
    /// `x, stats, gamma, beta, epsilon, relu, batch_stats`.
    type State = (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, f64, bool, bool);

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let ids = ops.parents.map(|node| node.map(|n| n.id));
        let grad = grads.consume::<B>(&ops.node);
        let (x, stats, gamma, beta, epsilon, relu, batch_stats) = ops.state;
        register_grads::<B>(grads, ids, [x, grad, stats, gamma, beta], epsilon, relu, batch_stats);
    }
}

/// Registers the gradients of features, γ and β (parents `[x, γ, β]`) of a batch norm whose
/// output gradient is `grad`: one `param_grads` pass, whose result the features' gradient needs
/// too. `tensors` are `[x, grad, stats, gamma, beta]`.
fn register_grads<B: BatchNormBackend>(grads: &mut Gradients, ids: [Option<NodeId>; 3], tensors: [FloatTensor<B>; 5], epsilon: f64, relu: bool, batch_stats: bool) {
    let [x_id, gamma_id, beta_id] = ids;
    let [x, grad, stats, gamma, beta] = tensors;
    let c = gamma.shape()[0];
    let params = B::batch_norm_param_grads(x.clone(), grad.clone(), stats.clone(), gamma.clone(), beta.clone(), epsilon, relu);
    let param_row = |i: usize| B::float_reshape(B::float_slice(params.clone(), &[Slice::from(i..i + 1), Slice::from(0..c)]), Shape::new([c]));
    if let Some(id) = gamma_id {
        grads.register::<B>(id, param_row(0));
    }
    if let Some(id) = beta_id {
        grads.register::<B>(id, param_row(1));
    }
    if let Some(id) = x_id {
        grads.register::<B>(id, B::batch_norm_input_grad(x, grad, stats, gamma, beta, params, epsilon, relu, batch_stats));
    }
}

#[derive(Debug)]
struct BatchNormAddReluBackward;

impl<B: BatchNormBackend> Backward<B, 4> for BatchNormAddReluBackward {
    /// `x, stats, gamma, beta, y (the output), epsilon, batch_stats`.
    type State = (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, f64, bool);

    /// Through the ReLU's mask first; what passes is the residual's gradient and the batch
    /// norm's output gradient.
    fn backward(self, ops: Ops<Self::State, 4>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let [x_id, gamma_id, beta_id, residual_id] = ops.parents.map(|node| node.map(|n| n.id));
        let grad = grads.consume::<B>(&ops.node);
        let (x, stats, gamma, beta, y, epsilon, batch_stats) = ops.state;
        let dz = B::batch_norm_relu_grad(y, grad);
        register_grads::<B>(grads, [x_id, gamma_id, beta_id], [x, dz.clone(), stats, gamma, beta], epsilon, false, batch_stats);
        if let Some(id) = residual_id {
            grads.register::<B>(id, dz);
        }
    }
}

/// Statistics are constants on `Autodiff` (the normalisation's backward accounts for them);
/// the gradient methods keep their composed, differentiable bodies.
impl<B: BatchNormBackend, C: CheckpointStrategy> BatchNormBackend for Autodiff<B, C> {
    fn batch_norm_stats(x: FloatTensor<Self>) -> FloatTensor<Self> {
        // A tensor with no autodiff node: Autodiff's float primitive built from the inner one.
        FloatTensor::<Self>::new(B::batch_norm_stats(x.primitive().clone()))
    }

    fn batch_norm_normalize(
        x: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
        relu: bool,
        batch_stats: bool,
    ) -> FloatTensor<Self> {
        let stats = stats.primitive().clone();
        match BatchNormBackward.prepare::<C>([x.node(), gamma.node(), beta.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (x, gamma, beta) = (x.primitive().clone(), gamma.primitive().clone(), beta.primitive().clone());
                let out = B::batch_norm_normalize(x.clone(), stats.clone(), gamma.clone(), beta.clone(), epsilon, relu, batch_stats);
                prep.finish((x, stats, gamma, beta, epsilon, relu, batch_stats), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::batch_norm_normalize(
                x.into_primitive(),
                stats,
                gamma.into_primitive(),
                beta.into_primitive(),
                epsilon,
                relu,
                batch_stats,
            )),
        }
    }

    fn batch_norm_add_relu(
        x: FloatTensor<Self>,
        stats: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        residual: FloatTensor<Self>,
        epsilon: f64,
        batch_stats: bool,
    ) -> FloatTensor<Self> {
        let stats = stats.primitive().clone();
        match BatchNormAddReluBackward.prepare::<C>([x.node(), gamma.node(), beta.node(), residual.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (x, gamma, beta) = (x.primitive().clone(), gamma.primitive().clone(), beta.primitive().clone());
                let y = B::batch_norm_add_relu(x.clone(), stats.clone(), gamma.clone(), beta.clone(), residual.into_primitive(), epsilon, batch_stats);
                prep.finish((x, stats, gamma, beta, y.clone(), epsilon, batch_stats), y)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::batch_norm_add_relu(
                x.into_primitive(),
                stats,
                gamma.into_primitive(),
                beta.into_primitive(),
                residual.into_primitive(),
                epsilon,
                batch_stats,
            )),
        }
    }
}

/// What the op applies to the normalised features before returning them.
// Built once per call and moved in: boxing the tensor would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Epilogue {
    /// Nothing: plain batch norm.
    Identity,
    /// `max(·, 0)`.
    Relu,
    /// `max(· + residual, 0)`, the end of a residual block; the residual is `[rows, C]`.
    AddRelu(Tensor<2>),
}

/// Batch norm of `[rows, C]` features with `stats` (`[2, C]`: mean; biased variance), then the
/// epilogue. `batch_stats` says the statistics are `x`'s own.
fn normalize(x: Tensor<2>, stats: Tensor<2>, gamma: Tensor<1>, beta: Tensor<1>, epsilon: f64, epilogue: Epilogue, batch_stats: bool) -> Tensor<2> {
    let (x, stats, gamma, beta) = (x.into_dispatch(), stats.into_dispatch(), gamma.into_dispatch(), beta.into_dispatch());
    Tensor::from_dispatch(match epilogue {
        Epilogue::Identity | Epilogue::Relu => {
            let relu = matches!(epilogue, Epilogue::Relu);
            <Dispatch as BatchNormBackend>::batch_norm_normalize(x, stats, gamma, beta, epsilon, relu, batch_stats)
        }
        Epilogue::AddRelu(residual) => {
            <Dispatch as BatchNormBackend>::batch_norm_add_relu(x, stats, gamma, beta, residual.into_dispatch(), epsilon, batch_stats)
        }
    })
}

/// Batch norm of `[rows, C]` features with their own batch statistics (training), then the
/// epilogue. Returns the output and the statistics `[2, C]` (mean; biased variance), constants,
/// for the running averages.
pub fn batch_norm_train(x: Tensor<2>, gamma: Tensor<1>, beta: Tensor<1>, epsilon: f64, epilogue: Epilogue) -> (Tensor<2>, Tensor<2>) {
    let stats = Tensor::from_dispatch(<Dispatch as BatchNormBackend>::batch_norm_stats(x.clone().into_dispatch()));
    (normalize(x, stats.clone(), gamma, beta, epsilon, epilogue, true), stats)
}

/// Batch norm of `[rows, C]` features with given statistics (inference: the running averages),
/// then the epilogue. Differentiable in `x`, `gamma`, `beta` and the residual.
pub fn batch_norm_eval(x: Tensor<2>, mean: Tensor<1>, var: Tensor<1>, gamma: Tensor<1>, beta: Tensor<1>, epsilon: f64, epilogue: Epilogue) -> Tensor<2> {
    let stats = Tensor::stack::<2>(vec![mean, var], 0);
    normalize(x, stats, gamma, beta, epsilon, epilogue, false)
}
