//! The same random case gives the same outputs and gradients on flex, ndarray and wgpu, and the
//! composed reference gives what the kernels give.

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::backend::composed;
use sparse_conv::burn::backend::Dispatch;
use sparse_conv::burn::tensor::{DType, Device, Tensor};
use sparse_conv::{CoordIndex, KernelMap, sparse_conv};

struct Outputs {
    out: Vec<f64>,
    gx: Vec<f64>,
    gw: Vec<f64>,
}

fn run(map: &Arc<KernelMap>, x: &[f64], w: &[f64], g: &[f64], c: [usize; 2], device: &Device) -> Outputs {
    let ad = device.clone().autodiff();
    let xt = tensor2(x, [map.n_in(), c[0]], &ad, DType::F32).require_grad();
    let wt = tensor3(w, [map.volume(), c[0], c[1]], &ad, DType::F32).require_grad();
    let out = sparse_conv(xt.clone(), wt.clone(), map);
    let grads = (out.clone() * tensor2(g, [map.n_out(), c[1]], &ad, DType::F32)).sum().backward();
    Outputs { out: values(out), gx: values(xt.grad(&grads).unwrap()), gw: values(wt.grad(&grads).unwrap()) }
}

#[test]
fn flex_ndarray_and_wgpu_agree() {
    let mut r = rng(21);
    let coords = random_coords(&mut r, 400, 2, 6, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let subm = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let (down, _) = KernelMap::down(&coords, 2, 1).unwrap();
    let up = Arc::new(down.transposed());
    let down = Arc::new(down);
    #[allow(deprecated)]
    let mut devices = vec![("flex", Device::flex()), ("ndarray", Device::ndarray())];
    if let Some(wgpu) = wgpu_device() {
        devices.push(("wgpu", wgpu));
    }
    eprintln!("comparing flex with: {:?}", devices[1..].iter().map(|(n, _)| *n).collect::<Vec<_>>());
    // A dense scene: enough pairs per offset that the GPU weight gradient sums several slices,
    // and (at 136 output channels, three column tiles) enough tiles that the GPU gather runs its
    // tiled kernel, the forward in one case and the feature gradient in the other.
    let dense_coords = random_coords(&mut r, 6000, 1, 12, 1);
    let dense = Arc::new(KernelMap::submanifold(&dense_coords, &CoordIndex::build(&dense_coords).unwrap(), 3, 1));
    // Channel counts: one GPU tile; several column tiles of both weight sides with partial last
    // ones (72 and 136 are 18 and 34 vectors of 4); vectors of 2.
    let cases = [("submanifold", &subm, [8, 16]), ("down", &down, [8, 16]), ("up", &up, [8, 16]), ("submanifold", &subm, [72, 136]), ("up", &up, [136, 72]), ("submanifold", &subm, [6, 10]), ("dense submanifold", &dense, [8, 16]), ("dense submanifold", &dense, [72, 136]), ("dense submanifold", &dense, [136, 72])];
    for (name, map, c) in cases {
        let x = random_values(&mut r, map.n_in() * c[0]);
        let w = random_values(&mut r, map.volume() * c[0] * c[1]);
        let g = random_values(&mut r, map.n_out() * c[1]);
        let reference = run(map, &x, &w, &g, c, &devices[0].1);
        for (device_name, device) in &devices[1..] {
            let other = run(map, &x, &w, &g, c, device);
            let what = format!("{name} {c:?} on {device_name} vs flex");
            assert_close(&other.out, &reference.out, 1e-5, &format!("{what}: output"));
            assert_close(&other.gx, &reference.gx, 1e-5, &format!("{what}: feature gradient"));
            assert_close(&other.gw, &reference.gw, 1e-5, &format!("{what}: weight gradient"));
        }
    }
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
        let kernels = run(&map, &x, &w, &g, c, &dev);
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
