//! Modules that run as the op where Burn has a layer of its own give that layer's results: the
//! per-voxel linear (a 1×1×1 convolution over the identity map) against `Linear::forward`, and a
//! 1×1×1 `SubmanifoldConv3d` against a matmul, with their gradients, on every backend; and the
//! channel concatenation of skip connections against Burn's `cat`.

mod common;

use common::*;
use sparse_conv::{SparseTensor, concat_channels};
use sparse_conv::burn::nn::LinearConfig;
use sparse_conv::burn::tensor::{DType, Tensor, TensorData};
use sparse_conv::modules::{SubmanifoldConv3dConfig, per_voxel_linear};

const ROWS: usize = 300;

#[test]
fn per_voxel_linear_matches_burns_linear() {
    for t in targets() {
        let ad = t.device.clone().autodiff();
        let (d_in, d_out) = (7, 5);
        let coords = random_coords(&mut rng(1), ROWS, 2, 6, 1);
        let w = random_values(&mut rng(2), d_in * d_out);
        let b = random_values(&mut rng(3), d_out);
        let g = tensor2(&random_values(&mut rng(4), ROWS * d_out), [ROWS, d_out], &ad, t.dtype);
        let run = |ours: bool| {
            let mut linear = LinearConfig::new(d_in, d_out).init(&ad);
            linear.weight = linear.weight.map(|_| tensor2(&w, [d_in, d_out], &ad, t.dtype).require_grad());
            linear.bias = linear.bias.map(|p| p.map(|_| Tensor::<1>::from_data(TensorData::new(b.clone(), [d_out]), (&ad, t.dtype)).require_grad()));
            let x = tensor2(&random_values(&mut rng(5), ROWS * d_in), [ROWS, d_in], &ad, t.dtype).require_grad();
            let y = if ours { per_voxel_linear(&linear, &SparseTensor::new(x.clone(), coords.clone()).unwrap()) } else { linear.forward(x.clone()) };
            let grads = (y.clone() * g.clone()).sum().backward();
            let bias = linear.bias.as_ref().unwrap();
            [values(y), values(x.grad(&grads).unwrap()), values(linear.weight.grad(&grads).unwrap()), values(bias.grad(&grads).unwrap())]
        };
        let (ours, burns) = (run(true), run(false));
        for (what, (a, e)) in ["output", "feature gradient", "weight gradient", "bias gradient"].iter().zip(ours.iter().zip(&burns)) {
            assert_close(a, e, t.tol * 10.0, &format!("{}: {what}", t.name));
        }
    }
}

#[test]
fn pointwise_submanifold_conv_is_a_matmul() {
    for t in targets() {
        let (c_in, c_out) = (6, 9);
        let coords = random_coords(&mut rng(6), ROWS, 1, 6, 1);
        let mut conv = SubmanifoldConv3dConfig::new([c_in, c_out]).with_kernel_size(1).init(&t.device);
        let w = random_values(&mut rng(7), c_in * c_out);
        conv.weight = conv.weight.map(|_| Tensor::<3>::from_data(TensorData::new(w.clone(), [1, c_in, c_out]), (&t.device, t.dtype)));
        let x = tensor2(&random_values(&mut rng(8), ROWS * c_in), [ROWS, c_in], &t.device, DType::F64).cast(t.dtype);
        let ours = values(conv.forward(SparseTensor::new(x.clone(), coords).unwrap()).into_features());
        let expected = values(x.matmul(tensor2(&w, [c_in, c_out], &t.device, t.dtype)));
        assert_close(&ours, &expected, t.tol * 10.0, &format!("{}: 1×1×1 conv", t.name));
    }
}

/// `concat_channels` equals Burn's `cat` along the channels, and its backward splits the
/// gradient into each side's channels (here with a non-uniform upstream gradient, and one side
/// used twice so its gradients add up).
#[test]
fn channel_concatenation_matches_burns_cat() {
    for t in targets() {
        let ad = t.device.clone().autodiff();
        let (c_a, c_b) = (5, 3);
        let g = tensor2(&random_values(&mut rng(9), ROWS * (c_a + c_b)), [ROWS, c_a + c_b], &ad, t.dtype);
        let run = |ours: bool| {
            let a = tensor2(&random_values(&mut rng(10), ROWS * c_a), [ROWS, c_a], &ad, t.dtype).require_grad();
            let b = tensor2(&random_values(&mut rng(11), ROWS * c_b), [ROWS, c_b], &ad, t.dtype).require_grad();
            let y = if ours { concat_channels(a.clone(), b.clone()) } else { Tensor::cat(vec![a.clone(), b.clone()], 1) };
            let loss = (y.clone() * g.clone()).sum() + (b.clone() * b.clone()).sum();
            let grads = loss.backward();
            [values(y), values(a.grad(&grads).unwrap()), values(b.grad(&grads).unwrap())]
        };
        let (ours, burns) = (run(true), run(false));
        for (what, (a, e)) in ["output", "first side's gradient", "second side's gradient"].iter().zip(ours.iter().zip(&burns)) {
            assert_eq!(a.len(), e.len(), "{}: {what} size", t.name);
            assert_close(a, e, t.tol, &format!("{}: {what}", t.name));
        }
    }
}
