//! Channel concatenation of voxel features (a U-Net's skip connections) as one op with its own
//! backward.
//!
//! Why not Burn's `cat`: on ndarray, `cat` along the channels builds its result column by column
//! (a non-standard layout, so every later read of it is an element-by-element copy), and its
//! backward hands strided views of the gradient to the layers below, on every CPU backend. Here
//! both directions are one row-parallel copy into contiguous tensors; other backends run Burn's
//! `cat` and `slice` (the trait's default bodies).
#![allow(deprecated)]

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, TensorMetadata, backend_extension};
use burn::tensor::{Slice, Tensor};
#[cfg(feature = "cube")]
use burn_cubecl::CubeBackend;
use crate::ops::host::{Host, HostFloats, on_host};
use crate::kernels::cpu::{Element, filled_in_chunks};

/// A backend that concatenates and splits `[rows, C]` features along the channels.
#[backend_extension(NdArray, Flex, Cube: cfg(feature = "cube"), Fusion: cfg(feature = "cube"), Autodiff)]
pub trait ChannelConcatBackend: Backend {
    /// `[a | b]` row by row: `[rows, C_a + C_b]`.
    #[fusion(dtype = a, shape = burn::tensor::Shape::new([a[0], a[1] + b[1]]))]
    fn concat_channels(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::float_cat(vec![a, b], 1)
    }

    /// Channels `start..end` of `x`, `[rows, end − start]`.
    #[fusion(dtype = x, shape = burn::tensor::Shape::new([x[0], end - start]))]
    fn channel_range(x: FloatTensor<Self>, start: usize, end: usize) -> FloatTensor<Self> {
        let rows = x.shape()[0];
        Self::float_slice(x, &[Slice::from(0..rows), Slice::from(start..end)])
    }
}

/// Rows per parallel task.
const CHUNK_ROWS: usize = 1024;

/// `[a | b]` row by row, for `a` of `c_a` and `b` of `c_b` channels.
pub fn concat_rows<T: Element>(a: &[T], c_a: usize, b: &[T], c_b: usize) -> Vec<T> {
    let c = c_a + c_b;
    let rows = a.len().checked_div(c_a).or(b.len().checked_div(c_b)).unwrap_or(0);
    assert!(a.len() == rows * c_a && b.len() == rows * c_b, "concatenated features must have the same rows");
    filled_in_chunks(rows * c, CHUNK_ROWS * c, |chunk, dst| {
        let first = chunk * CHUNK_ROWS;
        for (r, row) in dst.chunks_exact_mut(c).enumerate() {
            let (left, right) = row.split_at_mut(c_a);
            for (d, &s) in left.iter_mut().zip(&a[(first + r) * c_a..][..c_a]) {
                d.write(s);
            }
            for (d, &s) in right.iter_mut().zip(&b[(first + r) * c_b..][..c_b]) {
                d.write(s);
            }
        }
    })
}

/// Channels `start..end` of the `c`-channel rows of `x`, contiguous.
pub fn channel_rows<T: Element>(x: &[T], c: usize, start: usize, end: usize) -> Vec<T> {
    assert!(start <= end && end <= c, "channel range {start}..{end} outside {c} channels");
    let width = end - start;
    let rows = x.len().checked_div(c).unwrap_or(0);
    filled_in_chunks(rows * width, CHUNK_ROWS * width, |chunk, dst| {
        let first = chunk * CHUNK_ROWS;
        for (r, row) in dst.chunks_exact_mut(width).enumerate() {
            for (d, &s) in row.iter_mut().zip(&x[(first + r) * c + start..][..width]) {
                d.write(s);
            }
        }
    })
}

/// The CPU kernels, on every backend that keeps its values on the host (flex, ndarray).
impl<B: HostFloats> ChannelConcatBackend for B {
    fn concat_channels(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        let (sa, sb) = (a.shape(), b.shape());
        assert!(sa.num_dims() == 2 && sb.num_dims() == 2 && sa[0] == sb[0], "channel concatenation needs [rows, C] features of equal rows, got {sa:?} and {sb:?}");
        on_host!(Self, [a, b], [sa[0], sa[1] + sb[1]], |T| concat_rows(&T::host::<Self>(&a), sa[1], &T::host::<Self>(&b), sb[1]))
    }
    fn channel_range(x: FloatTensor<Self>, start: usize, end: usize) -> FloatTensor<Self> {
        let s = x.shape();
        assert_eq!(s.num_dims(), 2, "channel range of [rows, C] features, got {s:?}");
        on_host!(Self, [x], [s[0], end - start], |T| channel_rows(&T::host::<Self>(&x), s[1], start, end))
    }
}

/// Burn's `cat` and `slice` (the trait's default bodies).
#[cfg(feature = "cube")]
impl ChannelConcatBackend for CubeBackend {}

#[derive(Debug)]
struct ConcatBackward;

impl<B: ChannelConcatBackend> Backward<B, 2> for ConcatBackward {
    /// The channels of `a` and of `b`.
    type State = (usize, usize);

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let [node_a, node_b] = ops.parents;
        let grad = grads.consume::<B>(&ops.node);
        let (c_a, c_b) = ops.state;
        if let Some(node) = node_a {
            grads.register::<B>(node.id, B::channel_range(grad.clone(), 0, c_a));
        }
        if let Some(node) = node_b {
            grads.register::<B>(node.id, B::channel_range(grad, c_a, c_a + c_b));
        }
    }
}

/// The split is a copy, nothing to differentiate through twice: `channel_range` keeps its
/// composed body on `Autodiff`.
impl<B: ChannelConcatBackend, C: CheckpointStrategy> ChannelConcatBackend for Autodiff<B, C> {
    fn concat_channels(a: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        let (c_a, c_b) = (a.shape()[1], b.shape()[1]);
        match ConcatBackward.prepare::<C>([a.node(), b.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => prep.finish((c_a, c_b), B::concat_channels(a.primitive().clone(), b.primitive().clone())),
            OpsKind::UnTracked(prep) => prep.finish(B::concat_channels(a.into_primitive(), b.into_primitive())),
        }
    }
}

/// `[a | b]` along the channels of `[rows, C]` features, differentiable in both.
pub fn concat_channels(a: Tensor<2>, b: Tensor<2>) -> Tensor<2> {
    Tensor::from_dispatch(<Dispatch as ChannelConcatBackend>::concat_channels(a.into_dispatch(), b.into_dispatch()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_join_and_split_back() {
        let a: Vec<f32> = (0..3 * 2).map(|i| i as f32).collect();
        let b: Vec<f32> = (0..3 * 3).map(|i| 100.0 + i as f32).collect();
        let ab = concat_rows(&a, 2, &b, 3);
        assert_eq!(ab, vec![0.0, 1.0, 100.0, 101.0, 102.0, 2.0, 3.0, 103.0, 104.0, 105.0, 4.0, 5.0, 106.0, 107.0, 108.0]);
        assert_eq!(channel_rows(&ab, 5, 0, 2), a);
        assert_eq!(channel_rows(&ab, 5, 2, 5), b);
        assert!(concat_rows::<f32>(&[], 0, &[], 4).is_empty());
    }

    /// Many chunks, in parallel.
    #[test]
    fn large_inputs_cross_chunks() {
        let rows = 3 * CHUNK_ROWS + 7;
        let a: Vec<f64> = (0..rows * 3).map(|i| i as f64).collect();
        let b: Vec<f64> = (0..rows).map(|i| -(i as f64)).collect();
        let ab = concat_rows(&a, 3, &b, 1);
        for r in [0, CHUNK_ROWS - 1, CHUNK_ROWS, rows - 1] {
            assert_eq!(&ab[r * 4..r * 4 + 3], &a[r * 3..r * 3 + 3]);
            assert_eq!(ab[r * 4 + 3], b[r]);
        }
        assert_eq!(channel_rows(&ab, 4, 3, 4), b);
    }
}
