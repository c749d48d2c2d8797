//! Adam with the parameter and both moments updated in one pass: the optimiser pmunet trains
//! with.
//!
//! Why not Burn's `Adam` as is: its step is about a dozen element-wise tensor ops per parameter
//! (scaled moments, a square, a square root, the bias corrections), each a pass over the
//! parameter into a new buffer; on the CPU backends that is ~0.11 s of a 2.5 s MinkUNet training
//! step (21.7 M parameters). Here the CPU backends run `kernels::cpu::adam::adam_update`, one pass, and GPUs (the
//! cubecl backends, f32) one kernel per parameter; anything else composes the same math from
//! Burn's primitives ([`composed`]). The state is Burn's
//! [`AdamState`], so either optimiser resumes the other's checkpoints. With AMSGrad the step
//! divides by the running maximum of m₂, kept in the state as Burn keeps it.
//!
//! The arithmetic is Burn's, operation for operation, in the parameter's type: with `g` the
//! gradient (plus `λ·θ` with weight decay λ), `m₁ = β₁·m₁ + (1 − β₁)·g`,
//! `m₂ = β₂·m₂ + (1 − β₂)·g²`, and `θ = θ − lr·(m₁·c) / (√m₂ + ε·b)` with `b = √(1 − β₂ᵗ)` and
//! `c = b / (1 − β₁ᵗ)`, the scalars computed in f32 as Burn does.
#![allow(deprecated)]

use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Scalar, TensorMetadata, backend_extension};
use burn::config::Config;
use burn::grad_clipping::GradientClippingConfig;
use burn::optim::decay::WeightDecayConfig;
use burn::optim::{Adam, AdamState, AdaptiveMomentumState, LearningRate, ModuleOptimizer, Optimizer};
use burn::tensor::{Device, Shape, Slice, Tensor};
#[cfg(feature = "cube")]
use burn_cubecl::CubeBackend;

use crate::ops::host::{Host, HostFloats, on_host};
use crate::kernels::cpu::adam::{AdamScalars, adam_update};

/// A backend that runs one Adam step of a flat parameter.
#[backend_extension(NdArray, Flex, Cube: cfg(feature = "cube"), Fusion: cfg(feature = "cube"), Autodiff)]
pub trait AdamBackend: Backend {
    /// `[θ'; m₁'; m₂']` as `[3, n]`, from the flat `[n]` parameter `θ`, its gradient and moments
    /// (zeros before the first step); with `amsgrad` `[θ'; m₁'; m₂'; max(m̂₂, m₂')]` as `[4, n]`
    /// from the running maximum `max_moment_2` (ignored without). The scalars are
    /// [`AdamScalars`]' fields.
    #[allow(clippy::too_many_arguments)]
    #[fusion(dtype = param, shape = Shape::new([3 + usize::from(*amsgrad), param[0]]))]
    fn adam_step(
        param: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        moment_1: FloatTensor<Self>,
        moment_2: FloatTensor<Self>,
        max_moment_2: FloatTensor<Self>,
        amsgrad: bool,
        lr: f64,
        beta_1: f64,
        beta_2: f64,
        weight_decay: f64,
        correction: f64,
        epsilon: f64,
    ) -> FloatTensor<Self> {
        composed::<Self>(param, grad, moment_1, moment_2, max_moment_2, amsgrad, lr, beta_1, beta_2, weight_decay, correction, epsilon)
    }
}

/// [`AdamBackend::adam_step`] composed of Burn's primitives: what backends without a kernel of
/// their own run.
#[allow(clippy::too_many_arguments)]
pub fn composed<B: Backend>(
    param: FloatTensor<B>,
    grad: FloatTensor<B>,
    moment_1: FloatTensor<B>,
    moment_2: FloatTensor<B>,
    max_moment_2: FloatTensor<B>,
    amsgrad: bool,
    lr: f64,
    beta_1: f64,
    beta_2: f64,
    weight_decay: f64,
    correction: f64,
    epsilon: f64,
) -> FloatTensor<B> {
    let n = param.shape()[0];
    let s = |v: f64| Scalar::Float(v);
    let grad = match weight_decay {
        0.0 => grad,
        wd => B::float_add(B::float_mul_scalar(param.clone(), s(wd)), grad),
    };
    let moment_1 = B::float_add(B::float_mul_scalar(moment_1, s(beta_1)), B::float_mul_scalar(grad.clone(), s((1.0 - beta_1 as f32) as f64)));
    let moment_2 = B::float_add(B::float_mul_scalar(moment_2, s(beta_2)), B::float_mul_scalar(B::float_mul(grad.clone(), grad), s((1.0 - beta_2 as f32) as f64)));
    // AMSGrad divides by the running maximum of m₂ (Burn's `max_pair`: the new m₂ where the old
    // maximum is lower).
    let max_moment_2 = amsgrad.then(|| {
        let bool_dtype = burn::backend::get_or_init_device_settings::<B>(&param.device()).bool_dtype;
        let lower = B::float_lower(max_moment_2.clone(), moment_2.clone(), bool_dtype);
        B::float_mask_where(max_moment_2, lower, moment_2.clone())
    });
    let denominator = max_moment_2.clone().unwrap_or_else(|| moment_2.clone());
    let step = B::float_div(B::float_mul_scalar(moment_1.clone(), s(correction)), B::float_add_scalar(B::float_sqrt(denominator), s(epsilon)));
    let param = B::float_sub(param, B::float_mul_scalar(step, s(lr)));
    let row = |t: FloatTensor<B>| B::float_reshape(t, Shape::new([1, n]));
    B::float_cat([param, moment_1, moment_2].into_iter().chain(max_moment_2).map(row).collect(), 0)
}


/// The CPU kernels, on every backend that keeps its values on the host (flex, ndarray).
impl<B: HostFloats> AdamBackend for B {
    fn adam_step(
        param: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        moment_1: FloatTensor<Self>,
        moment_2: FloatTensor<Self>,
        max_moment_2: FloatTensor<Self>,
        amsgrad: bool,
        lr: f64,
        beta_1: f64,
        beta_2: f64,
        weight_decay: f64,
        correction: f64,
        epsilon: f64,
    ) -> FloatTensor<Self> {
        let n = param.shape().num_elements();
        on_host!(Self, [param, grad, moment_1, moment_2, max_moment_2], [3 + amsgrad as usize, n], |T| {
            let s = AdamScalars::<T>::new(lr, beta_1, beta_2, weight_decay, correction, epsilon);
            let max = amsgrad.then(|| T::host::<Self>(&max_moment_2));
            adam_update(&T::host::<Self>(&param), &T::host::<Self>(&grad), &T::host::<Self>(&moment_1), &T::host::<Self>(&moment_2), max.as_deref(), s)
        })
    }
}

/// The f32 kernel of [`crate::kernels::cube`], Burn's primitives for other dtypes.
#[cfg(feature = "cube")]
impl AdamBackend for CubeBackend {
    fn adam_step(
        param: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        moment_1: FloatTensor<Self>,
        moment_2: FloatTensor<Self>,
        max_moment_2: FloatTensor<Self>,
        amsgrad: bool,
        lr: f64,
        beta_1: f64,
        beta_2: f64,
        weight_decay: f64,
        correction: f64,
        epsilon: f64,
    ) -> FloatTensor<Self> {
        if !crate::kernels::cube::runs(&param) {
            return composed::<Self>(param, grad, moment_1, moment_2, max_moment_2, amsgrad, lr, beta_1, beta_2, weight_decay, correction, epsilon);
        }
        let scalars = AdamScalars::<f32>::new(lr, beta_1, beta_2, weight_decay, correction, epsilon);
        crate::kernels::cube::adam_step(param, grad, moment_1, moment_2, amsgrad.then_some(max_moment_2), scalars)
    }
}

/// The optimiser steps inner (non-differentiable) tensors; on `Autodiff` the default body
/// composes differentiable primitives.
impl<B: AdamBackend, C: CheckpointStrategy> AdamBackend for Autodiff<B, C> {}

/// [`FusedAdam`]'s settings: [`AdamConfig`]'s fields, with its defaults.
#[derive(Config, Debug)]
pub struct FusedAdamConfig {
    #[config(default = 0.9)]
    /// β₁ (0.9).
    pub beta_1: f32,
    #[config(default = 0.999)]
    /// β₂ (0.999).
    pub beta_2: f32,
    #[config(default = 1e-5)]
    /// ε (1e-5, Burn's default).
    pub epsilon: f32,
    #[config(default = false)]
    /// AMSGrad: divide by the running maximum of m₂.
    pub amsgrad: bool,
    /// L2 weight decay added to the gradient.
    pub weight_decay: Option<WeightDecayConfig>,
    /// Gradient clipping before the step.
    pub grad_clipping: Option<GradientClippingConfig>,
}

impl FusedAdamConfig {
    /// The optimiser, ready for `step`.
    pub fn init(&self) -> ModuleOptimizer {
        let adam = FusedAdam {
            beta_1: self.beta_1,
            beta_2: self.beta_2,
            epsilon: self.epsilon,
            weight_decay: self.weight_decay.as_ref().map_or(0.0, |w| w.penalty),
            amsgrad: self.amsgrad,
        };
        let mut optim = ModuleOptimizer::from(adam);
        if let Some(clipping) = &self.grad_clipping {
            optim = optim.with_grad_clipping(clipping.init());
        }
        optim
    }
}

/// Adam whose step is one [`AdamBackend::adam_step`] per parameter.
#[derive(Clone)]
pub struct FusedAdam {
    beta_1: f32,
    beta_2: f32,
    epsilon: f32,
    weight_decay: f32,
    amsgrad: bool,
}

impl Optimizer for FusedAdam {
    type State<const D: usize> = AdamState<D>;

    fn step<const D: usize>(&self, lr: LearningRate, tensor: Tensor<D>, grad: Tensor<D>, state: Option<Self::State<D>>) -> (Tensor<D>, Option<Self::State<D>>) {
        let shape = tensor.shape();
        let n = shape.num_elements();
        let flat = |t: Tensor<D>| t.reshape([n]);
        // Zero moments of the parameter's dtype: the first step's sums are then Burn's, and a zero
        // running maximum gives way to the first m₂ (never negative), as Burn starts it.
        let zeros = || flat(tensor.zeros_like());
        let (time, moment_1, moment_2, max_moment_2) = match state {
            Some(s) => (s.momentum.time + 1, flat(s.momentum.moment_1), flat(s.momentum.moment_2), s.momentum.max_moment_2.map(flat)),
            None => (1, zeros(), zeros(), None),
        };
        let max_moment_2 = if self.amsgrad { max_moment_2.unwrap_or_else(zeros) } else { moment_2.clone() };
        // Burn's scalars, in f32 as Burn computes them.
        let t = time as i32;
        let bias_correction_2 = (1.0 - self.beta_2.powi(t)).sqrt();
        let correction = bias_correction_2 / (1.0 - self.beta_1.powi(t));
        let out = <Dispatch as AdamBackend>::adam_step(
            flat(tensor).into_dispatch(),
            flat(grad).into_dispatch(),
            moment_1.into_dispatch(),
            moment_2.into_dispatch(),
            max_moment_2.into_dispatch(),
            self.amsgrad,
            lr as f32 as f64,
            self.beta_1 as f64,
            self.beta_2 as f64,
            self.weight_decay as f64,
            correction as f64,
            (self.epsilon * bias_correction_2) as f64,
        );
        let out: Tensor<2> = Tensor::from_dispatch(out);
        let row = |i: usize| out.clone().slice([Slice::from(i..i + 1), Slice::from(0..n)]).reshape(shape.clone());
        let mut momentum = AdaptiveMomentumState::new(time, row(1), row(2));
        momentum.max_moment_2 = self.amsgrad.then(|| row(3));
        (row(0), Some(AdamState::new(momentum)))
    }

    fn to_device<const D: usize>(state: Self::State<D>, device: &Device) -> Self::State<D> {
        <Adam as Optimizer>::to_device(state, device)
    }
}
