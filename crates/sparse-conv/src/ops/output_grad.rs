//! A backward pass started from a given gradient of an output, PyTorch's `out.backward(grad)`.
//!
//! Why: Burn 0.22 starts a backward from a loss, so timing an op's backward means adding a loss
//! such as `sum`, whose own backward (a `ones` of the output's shape, filled serially on
//! ndarray, times the incoming gradient) costs a few ms at 35k × 64, more than a cheap op's
//! kernel. The peer benchmark hands its backward a ready gradient; this does the same, and lets
//! a user chain a gradient computed elsewhere into a graph.
#![allow(deprecated)]

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Flex, NdArray, TensorMetadata, backend_extension};
use burn::tensor::{Shape, Tensor};
#[cfg(feature = "cube")]
use burn_cubecl::CubeBackend;

/// A backend that can root a backward pass at a tensor with a given gradient.
#[backend_extension(NdArray, Flex, Cube: cfg(feature = "cube"), Fusion: cfg(feature = "cube"), Autodiff)]
pub trait OutputGradBackend: Backend {
    /// A one-element tensor whose backward hands `grad` to `output`. Without autodiff there is
    /// nothing to hand on: a zero.
    #[fusion(dtype = output, shape = Shape::new([1]))]
    fn output_grad_root(output: FloatTensor<Self>, grad: FloatTensor<Self>) -> FloatTensor<Self> {
        let _ = grad;
        Self::float_zeros(Shape::new([1]), &output.device(), output.dtype().into())
    }
}

impl OutputGradBackend for NdArray {}
impl OutputGradBackend for Flex {}
#[cfg(feature = "cube")]
impl OutputGradBackend for CubeBackend {}

#[derive(Debug)]
struct OutputGradBackward;

impl<B: Backend> Backward<B, 1> for OutputGradBackward {
    /// The gradient to hand on.
    type State = FloatTensor<B>;

    /// The root's own (seed) gradient is dropped: `grad` is the output's gradient by definition.
    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let [node] = ops.parents;
        drop(grads.consume::<B>(&ops.node));
        if let Some(node) = node {
            grads.register::<B>(node.id, ops.state);
        }
    }
}

impl<B: OutputGradBackend, C: CheckpointStrategy> OutputGradBackend for Autodiff<B, C> {
    fn output_grad_root(output: FloatTensor<Self>, grad: FloatTensor<Self>) -> FloatTensor<Self> {
        let (shape, device, dtype) = (output.shape(), output.device(), output.dtype());
        assert_eq!(grad.shape(), shape, "an output's gradient must have the output's shape");
        let root = || B::float_zeros(Shape::new([1]), &device, dtype.into());
        match OutputGradBackward.prepare::<C>([output.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => prep.finish(grad.into_primitive(), root()),
            OpsKind::UnTracked(prep) => prep.finish(root()),
        }
    }
}

/// Runs the backward pass through `output`'s graph with `grad` as `output`'s gradient, like
/// PyTorch's `output.backward(grad)`. `grad` is used as it is (not copied, not tracked).
///
/// # Panics
/// If `output` is not tracked by autodiff or `grad`'s shape differs from `output`'s.
pub fn backward_from<const D: usize>(output: Tensor<D>, grad: Tensor<D>) -> burn::tensor::Gradients {
    let root = Tensor::<1>::from_dispatch(<Dispatch as OutputGradBackend>::output_grad_root(output.into_dispatch(), grad.detach().into_dispatch()));
    root.backward()
}
