//! The same random case gives the same outputs and gradients on flex, ndarray and wgpu, and the
//! composed reference gives what the kernels give.

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::ops::conv::composed;
use sparse_conv::burn::backend::Dispatch;
use sparse_conv::burn::tensor::{DType, Device, Tensor};
use sparse_conv::{CoordIndex, KernelMap};

#[test]
fn flex_ndarray_and_wgpu_agree() {
    backends_agree_on_random_cases();
}

/// The composition of Burn primitives (the trait's default bodies: what a backend without
/// kernels of its own, a second derivative, or a non-f32 dtype on wgpu runs) computes what the
/// kernels compute, for all three methods on every map kind.
#[test]
fn composed_reference_agrees_with_the_kernels() {
    let mut r = rng(22);
    let coords = random_coords(&mut r, 300, 2, 6, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let subm = KernelMap::submanifold(&coords, &index, 3, 1);
    let (down, _) = KernelMap::down(&coords, 2, 1).unwrap();
    let up = down.transposed();
    let dev = Device::flex();
    let c = [5, 7];
    for (name, map) in [("submanifold", Arc::new(subm)), ("down", Arc::new(down)), ("up", Arc::new(up))] {
        let x = random_values(&mut r, map.n_in() * c[0]);
        let w = random_values(&mut r, map.volume() * c[0] * c[1]);
        let g = random_values(&mut r, map.n_out() * c[1]);
        let kernels = conv_outputs(&map, &x, &w, &g, c, &dev);
        let (xt, wt) = (tensor2(&x, [map.n_in(), c[0]], &dev, DType::F32), tensor3(&w, [map.volume(), c[0], c[1]], &dev, DType::F32));
        let gt = tensor2(&g, [map.n_out(), c[1]], &dev, DType::F32);
        let out = Tensor::<2>::from_dispatch(composed::forward::<Dispatch>(xt.clone().into_dispatch(), wt.clone().into_dispatch(), &map));
        let gx = Tensor::<2>::from_dispatch(composed::input_grad::<Dispatch>(gt.clone().into_dispatch(), wt.into_dispatch(), &map));
        let gw = Tensor::<3>::from_dispatch(composed::weight_grad::<Dispatch>(xt.into_dispatch(), gt.into_dispatch(), &map));
        assert_close(&values(out), &kernels.out, 1e-5, &format!("{name}: composed output"));
        assert_close(&values(gx), &kernels.gx, 1e-5, &format!("{name}: composed feature gradient"));
        assert_close(&values(gw), &kernels.gw, 1e-5, &format!("{name}: composed weight gradient"));
    }
}

/// A `SparseTensor` on wgpu builds its submanifold maps on the device: after a forward and
/// backward pass nothing on the host has built their tables, and the output and gradients are
/// flex's (which builds them on the host).
#[test]
fn a_gpu_tensor_builds_its_submanifold_maps_on_the_device() {
    let Some(wgpu) = wgpu_device() else { return };
    let mut r = rng(23);
    let coords = random_coords(&mut r, 3000, 2, 10, 1);
    let (c_in, c_out) = (8, 12);
    let x = random_values(&mut r, coords.len() * c_in);
    let w = random_values(&mut r, 27 * c_in * c_out);
    let run = |device: &Device| {
        let ad = device.clone().autodiff();
        let xt = tensor2(&x, [coords.len(), c_in], &ad, DType::F32).require_grad();
        let wt = tensor3(&w, [27, c_in, c_out], &ad, DType::F32).require_grad();
        let input = sparse_conv::SparseTensor::new(xt.clone(), coords.clone()).unwrap();
        let map = input.submanifold_map(3);
        let out = sparse_conv::sparse_conv(input.features(), wt.clone(), &map);
        let grads = (out.clone() * out.clone()).sum().backward();
        let host_tables = map.has_host_tables();
        (values(out), values(xt.grad(&grads).unwrap()), values(wt.grad(&grads).unwrap()), host_tables)
    };
    let (out, gx, gw, host_tables) = run(&wgpu);
    assert!(!host_tables, "the host built a GPU tensor's submanifold tables");
    let (out_flex, gx_flex, gw_flex, host_tables_flex) = run(&Device::flex());
    assert!(host_tables_flex);
    assert_close(&out, &out_flex, 1e-5, "output");
    assert_close(&gx, &gx_flex, 1e-5, "feature gradient");
    assert_close(&gw, &gw_flex, 1e-5, "weight gradient");
}

/// On wgpu a U-Net's levels are made on the device: after a down-sampling, a submanifold conv on
/// the coarse level and the transposed conv back, forward and backward, the coarse level's
/// coordinates never came to the host and no map built host tables; outputs and gradients are
/// flex's.
#[test]
fn a_gpu_tensor_makes_its_coarse_levels_on_the_device() {
    use sparse_conv::burn::module::Param;
    use sparse_conv::modules::{SparseConv3d, SparseConvTranspose3d, SubmanifoldConv3d};
    let Some(wgpu) = wgpu_device() else { return };
    let mut r = rng(29);
    // Negative coordinates too: the coarse voxels are floors, not truncations.
    let coords: Vec<_> = random_coords(&mut r, 4000, 2, 12, 1).into_iter().map(|c| [c[0], c[1] - 6, c[2] - 5, c[3]]).collect();
    let c = [6, 10, 7];
    let x = random_values(&mut r, coords.len() * c[0]);
    let w = [random_values(&mut r, 8 * c[0] * c[1]), random_values(&mut r, 27 * c[1] * c[1]), random_values(&mut r, 8 * c[1] * c[2])];
    let run = |device: &Device| {
        let ad = device.clone().autodiff();
        let param = |i: usize, k: usize, shape: [usize; 2]| Param::from_tensor(tensor3(&w[i], [k, shape[0], shape[1]], &ad, DType::F32));
        let down = SparseConv3d { weight: param(0, 8, [c[0], c[1]]), kernel_size: 2, tied: None };
        let coarse_conv = SubmanifoldConv3d { weight: param(1, 27, [c[1], c[1]]), kernel_size: 3, tied: None };
        let up = SparseConvTranspose3d { weight: param(2, 8, [c[1], c[2]]), kernel_size: 2, tied: None };
        let xt = tensor2(&x, [coords.len(), c[0]], &ad, DType::F32).require_grad();
        let input = sparse_conv::SparseTensor::new(xt.clone(), coords.clone()).unwrap();
        let coarse = coarse_conv.forward(down.forward(input.clone()));
        let out = up.forward(coarse.clone());
        assert_eq!(out.num_voxels(), coords.len());
        let features = out.into_features();
        let grads = (features.clone() * features.clone()).sum().backward();
        let maps = [input.down_map(2).0, coarse.submanifold_map(3), coarse.up_map(2).0];
        let on_host = (coarse.level().is_on_host(), maps.iter().map(|m| m.has_host_tables()).collect::<Vec<_>>());
        let gw: Vec<Vec<f64>> = [&down.weight, &coarse_conv.weight, &up.weight].iter().map(|p| values(p.val().grad(&grads).unwrap())).collect();
        (values(features), values(xt.grad(&grads).unwrap()), gw, coarse.num_voxels(), on_host)
    };
    let (out, gx, gw, coarse, on_host) = run(&wgpu);
    assert_eq!(on_host, (false, vec![false; 3]), "(coarse coordinates on the host, maps with host tables) on wgpu");
    let (out_flex, gx_flex, gw_flex, coarse_flex, on_host_flex) = run(&Device::flex());
    assert_eq!(on_host_flex, (true, vec![true; 3]));
    assert_eq!(coarse, coarse_flex, "coarse voxels");
    assert_close(&out, &out_flex, 1e-5, "output");
    assert_close(&gx, &gx_flex, 1e-5, "feature gradient");
    for (i, (a, b)) in gw.iter().zip(&gw_flex).enumerate() {
        assert_close(a, b, 1e-5, &format!("weight gradient of layer {i}"));
    }
}
