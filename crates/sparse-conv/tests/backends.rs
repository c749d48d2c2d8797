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
