//! The op's forward on every map kind and every backend (flex, ndarray, the CubeCL kernel on
//! wgpu) equals a dense 3D convolution (Burn's `conv3d` and `conv_transpose3d` on a zero-filled
//! grid, in f64 on flex) on random sparse grids with negative coordinates and several batch
//! samples.

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::burn::tensor::Device;
use sparse_conv::{CoordIndex, KernelMap, sparse_conv};

/// Where the dense reference runs.
fn reference_device() -> Device {
    Device::flex()
}

fn check_submanifold(kernel: usize, stride: i32, seed: u64) {
    for target in targets() {
        check_submanifold_on(&target, kernel, stride, seed);
    }
}

fn check_submanifold_on(target: &Target, kernel: usize, stride: i32, seed: u64) {
    let (dev, dtype) = (&target.device, target.dtype);
    let mut r = rng(seed);
    let (c_in, c_out) = (3, 4);
    let coords = random_coords(&mut r, 150, 3, 5, stride);
    let volume = kernel.pow(3);
    let x = random_values(&mut r, coords.len() * c_in);
    let w = random_values(&mut r, volume * c_in * c_out);
    let index = CoordIndex::build(&coords).unwrap();
    let map = Arc::new(KernelMap::submanifold(&coords, &index, kernel, stride));
    let out = sparse_conv(tensor2(&x, [coords.len(), c_in], dev, dtype), tensor3(&w, [volume, c_in, c_out], dev, dtype), &map);
    let actual = by_coord(&coords, &values(out), c_out);
    let expected = dense_reference(DenseKind::Submanifold(kernel), &coords, &x, c_in, &w, c_out, stride, &[], &reference_device());
    assert_maps_close(&actual, &expected, target.tol, &format!("{}: submanifold k={kernel} s={stride}", target.name));
}

#[test]
fn submanifold_k3_matches_dense() {
    check_submanifold(3, 1, 1);
}

#[test]
fn submanifold_k1_and_k5_match_dense() {
    check_submanifold(1, 1, 2);
    check_submanifold(5, 1, 3);
}

#[test]
fn submanifold_at_tensor_stride_4_matches_dense() {
    check_submanifold(3, 4, 4);
}

#[test]
fn down_and_up_match_dense() {
    for target in targets() {
        down_and_up_match_dense_on(&target);
    }
}

fn down_and_up_match_dense_on(target: &Target) {
    let (dev, dtype, tol, name) = (&target.device, target.dtype, target.tol, target.name);
    let reference = reference_device();
    for (stride, seed) in [(1, 5), (2, 6)] {
        let mut r = rng(seed);
        let (c_in, c_mid) = (3, 5);
        let coords = random_coords(&mut r, 200, 2, 6, stride);
        let x = random_values(&mut r, coords.len() * c_in);
        let w_down = random_values(&mut r, 8 * c_in * c_mid);
        let (down, coarse) = KernelMap::down(&coords, 2, stride).unwrap();
        let down = Arc::new(down);
        let y = sparse_conv(tensor2(&x, [coords.len(), c_in], dev, dtype), tensor3(&w_down, [8, c_in, c_mid], dev, dtype), &down);
        let y = values(y);
        let expected = dense_reference(DenseKind::Down, &coords, &x, c_in, &w_down, c_mid, stride, &[], &reference);
        assert_maps_close(&by_coord(&coarse, &y, c_mid), &expected, tol, &format!("{name}: down from stride {stride}"));
        // Every coarse coordinate is floor(c / 2s)·2s of a child.
        for c in &coarse {
            assert!(c[1..].iter().all(|v| v % (2 * stride) == 0));
        }

        let c_out = 4;
        let w_up = random_values(&mut r, 8 * c_mid * c_out);
        let up = Arc::new(down.transposed());
        let z = sparse_conv(tensor2(&y, [coarse.len(), c_mid], dev, dtype), tensor3(&w_up, [8, c_mid, c_out], dev, dtype), &up);
        let expected = dense_reference(DenseKind::Up, &coarse, &y, c_mid, &w_up, c_out, 2 * stride, &coords, &reference);
        assert_maps_close(&by_coord(&coords, &values(z), c_out), &expected, tol, &format!("{name}: up to stride {stride}"));
    }
}

#[test]
fn batch_samples_never_interact() {
    for target in targets() {
        batch_samples_never_interact_on(&target);
    }
}

fn batch_samples_never_interact_on(target: &Target) {
    let (dev, dtype) = (&target.device, target.dtype);
    let mut r = rng(7);
    let coords = random_coords(&mut r, 100, 1, 3, 1);
    // The same voxels in sample 1, with other features: sample 0's output must not change.
    let mut both = coords.clone();
    both.extend(coords.iter().map(|c| [1, c[1], c[2], c[3]]));
    let x0 = random_values(&mut r, coords.len() * 2);
    let mut x = x0.clone();
    x.extend(random_values(&mut r, coords.len() * 2));
    let w = random_values(&mut r, 27 * 2 * 2);
    let run = |coords: &[sparse_conv::Coord], x: &[f64]| {
        let index = CoordIndex::build(coords).unwrap();
        let map = Arc::new(KernelMap::submanifold(coords, &index, 3, 1));
        values(sparse_conv(tensor2(x, [coords.len(), 2], dev, dtype), tensor3(&w, [27, 2, 2], dev, dtype), &map))
    };
    let alone = run(&coords, &x0);
    let together = run(&both, &x);
    assert_eq!(&together[..alone.len()], &alone[..], "{}", target.name);
}
