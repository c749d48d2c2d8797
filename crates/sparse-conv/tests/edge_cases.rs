//! Empty input, one voxel, a voxel with no neighbours, a level with a single parent, and strided
//! (transposed, broadcast) tensors, on every backend's kernels.

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::burn::tensor::{Device, Tensor};
use sparse_conv::{CoordIndex, KernelMap, SparseTensor, sparse_conv};

#[test]
fn empty_input_gives_empty_output_and_gradients() {
    for target in targets() {
        empty_input_on(&target.device);
    }
}

fn empty_input_on(dev: &Device) {
    let dev = dev.clone().autodiff();
    let coords: Vec<sparse_conv::Coord> = Vec::new();
    let index = CoordIndex::build(&coords).unwrap();
    let map = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let x = Tensor::<2>::zeros([0, 4], &dev).require_grad();
    let w = Tensor::<3>::ones([27, 4, 2], &dev).require_grad();
    let out = sparse_conv(x.clone(), w.clone(), &map);
    assert_eq!(out.dims(), [0, 2]);
    let grads = out.sum().backward();
    assert_eq!(values(w.grad(&grads).unwrap()), vec![0.0; 27 * 8]);
    let (down, coarse) = KernelMap::down(&coords, 2, 1).unwrap();
    assert_eq!((down.n_out(), coarse.len()), (0, 0));
}

#[test]
fn isolated_voxels_see_only_the_centre_weight() {
    for target in targets() {
        isolated_voxels_on(&target);
    }
}

fn isolated_voxels_on(target: &Target) {
    let (dev, dtype) = (&target.device, target.dtype);
    // One voxel alone, and a voxel two cells away from any other (no 3×3×3 neighbours).
    for coords in [vec![[0, 3, -4, 5]], vec![[0, 0, 0, 0], [0, 2, 0, 0], [1, 0, 0, 0]]] {
        let n = coords.len();
        let mut r = rng(41);
        let x = random_values(&mut r, n * 3);
        let w = random_values(&mut r, 27 * 3 * 2);
        let index = CoordIndex::build(&coords).unwrap();
        let map = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
        assert_eq!(map.num_pairs(), n);
        let out = values(sparse_conv(tensor2(&x, [n, 3], dev, dtype), tensor3(&w, [27, 3, 2], dev, dtype), &map));
        for row in 0..n {
            for co in 0..2 {
                let expected: f64 = (0..3).map(|ci| x[row * 3 + ci] * w[(13 * 3 + ci) * 2 + co]).sum();
                assert!((out[row * 2 + co] - expected).abs() < target.tol, "{}: {} vs {expected}", target.name, out[row * 2 + co]);
            }
        }
    }
}

#[test]
fn a_level_with_a_single_parent() {
    for target in targets() {
        single_parent_on(&target);
    }
}

fn single_parent_on(target: &Target) {
    let (dev, dtype) = (&target.device, target.dtype);
    // All eight children of the cell at the origin.
    let coords: Vec<_> = (0..8).map(|k| [0, (k >> 2) & 1, (k >> 1) & 1, k & 1]).collect();
    let (down, coarse) = KernelMap::down(&coords, 2, 1).unwrap();
    assert_eq!(coarse, vec![[0, 0, 0, 0]]);
    let x: Vec<f64> = (0..8).map(|i| i as f64 + 1.0).collect();
    let w: Vec<f64> = (0..8).map(|k| 10f64.powi(k)).collect();
    let down = Arc::new(down);
    let y = values(sparse_conv(tensor2(&x, [8, 1], dev, dtype), tensor3(&w, [8, 1, 1], dev, dtype), &down));
    // Child k (offset k) meets weight k: Σ (k+1)·10^k.
    let expected: f64 = (0..8).map(|k| (k as f64 + 1.0) * 10f64.powi(k)).sum();
    // Exact in f64; in f32 the sum (≈ 8.8e7) is exact to its 24-bit mantissa.
    assert_close(&y, &[expected], target.tol, target.name);
    let up = Arc::new(down.transposed());
    let z = values(sparse_conv(tensor2(&[2.0], [1, 1], dev, dtype), tensor3(&w, [8, 1, 1], dev, dtype), &up));
    assert_eq!(z, w.iter().map(|v| 2.0 * v).collect::<Vec<_>>(), "{}", target.name);
}

#[test]
fn sparse_tensor_rejects_bad_coordinates() {
    let dev = Device::flex();
    let err = SparseTensor::new(Tensor::zeros([2, 1], &dev), vec![[0, 1, 1, 1], [0, 1, 1, 1]]).unwrap_err();
    assert!(err.to_string().contains("appears twice"), "{err}");
    let err = SparseTensor::new(Tensor::zeros([3, 1], &dev), vec![[0, 1, 1, 1]]).unwrap_err();
    assert!(err.to_string().contains("3 feature rows for 1"), "{err}");
}

/// A transposed view as the features and a broadcast gradient seed give the values and gradients
/// of their contiguous copies (the CPU backends read strided views row by row).
#[test]
fn strided_tensors_give_the_results_of_contiguous_ones() {
    for t in targets() {
        let ad = t.device.clone().autodiff();
        let (n, c_in, c_out) = (200, 6, 4);
        let coords = random_coords(&mut rng(21), n, 2, 5, 1);
        let index = CoordIndex::build(&coords).unwrap();
        let map = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
        let x_t = random_values(&mut rng(22), c_in * n);
        let w = tensor3(&random_values(&mut rng(23), 27 * c_in * c_out), [27, c_in, c_out], &ad, t.dtype).require_grad();
        let run = |strided: bool| {
            // [C_in, n] stored, read as [n, C_in] through its transpose; the feature gradient is
            // returned as [C_in, n] both ways.
            let x = tensor2(&x_t, [c_in, n], &ad, t.dtype).require_grad();
            let copy = Tensor::<2>::from_data(x.clone().transpose().to_data(), (&ad, t.dtype)).require_grad();
            let features = if strided { x.clone().transpose() } else { copy.clone() };
            let out = sparse_conv(features, w.clone(), &map);
            // `sum`'s backward seeds a broadcast gradient; the product gives a plain one.
            let grads = if strided { out.clone().sum().backward() } else { (out.clone() * Tensor::<2>::ones([n, c_out], (&ad, t.dtype))).sum().backward() };
            let dx = if strided { x.grad(&grads).unwrap() } else { copy.grad(&grads).unwrap().transpose() };
            [values(out), values(w.grad(&grads).unwrap()), values(dx)]
        };
        let (strided, contiguous) = (run(true), run(false));
        for (what, (a, e)) in ["output", "weight gradient", "feature gradient"].iter().zip(strided.iter().zip(&contiguous)) {
            assert_close(a, e, t.tol * 10.0, &format!("{}: {what}", t.name));
        }
    }
}
