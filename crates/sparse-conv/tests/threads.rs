//! The op gives bit-identical outputs and gradients at 1, 2 and 8 threads, run repeatedly: a race
//! in a gather/scatter would show as rows that differ from run to run (the bug spconv 2.3.8's CPU
//! submanifold convolution has at 2 threads). The CubeCL kernel, whose units the GPU schedules as
//! it likes, must be as repeatable.

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::burn::tensor::{DType, Device};
use sparse_conv::{CoordIndex, KernelMap, sparse_conv};

fn forward_backward(map: &Arc<KernelMap>, x: &[f64], w: &[f64], g: &[f64], c: usize, device: &Device) -> [Vec<f64>; 3] {
    let ad = device.clone().autodiff();
    let xt = tensor2(x, [map.n_in(), c], &ad, DType::F32).require_grad();
    let wt = tensor3(w, [map.volume(), c, c], &ad, DType::F32).require_grad();
    let out = sparse_conv(xt.clone(), wt.clone(), map);
    let grads = (out.clone() * tensor2(g, [map.n_out(), c], &ad, DType::F32)).sum().backward();
    [values(out), values(xt.grad(&grads).unwrap()), values(wt.grad(&grads).unwrap())]
}

/// Dense enough that outputs have many neighbours and tiles and gradient chunks are many.
fn dense_case() -> (Arc<KernelMap>, Vec<f64>, Vec<f64>, Vec<f64>, usize) {
    case(20_000, 16)
}

/// Few pairs per offset and several column panels (with a partial one): the CPU kernel then
/// splits an offset's work by panels, more finely at more threads.
fn sparse_wide_case() -> (Arc<KernelMap>, Vec<f64>, Vec<f64>, Vec<f64>, usize) {
    case(1_500, 80)
}

fn case(voxels: usize, c: usize) -> (Arc<KernelMap>, Vec<f64>, Vec<f64>, Vec<f64>, usize) {
    let mut r = rng(31);
    let coords = random_coords(&mut r, voxels, 2, 24, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let map = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let x = random_values(&mut r, map.n_in() * c);
    let w = random_values(&mut r, map.volume() * c * c);
    let g = random_values(&mut r, map.n_out() * c);
    (map, x, w, g, c)
}

fn count_differing(a: &[f64], b: &[f64]) -> usize {
    a.iter().zip(b).filter(|(p, q)| p.to_bits() != q.to_bits()).count()
}

#[test]
fn results_do_not_depend_on_thread_count() {
    for (map, x, w, g, c) in [dense_case(), sparse_wide_case()] {
        same_results_at_every_thread_count(&map, &x, &w, &g, c);
    }
}

fn same_results_at_every_thread_count(map: &Arc<KernelMap>, x: &[f64], w: &[f64], g: &[f64], c: usize) {
    #[allow(deprecated)]
    for device in [Device::flex(), Device::ndarray()] {
        let single = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let reference = single.install(|| forward_backward(map, x, w, g, c, &device));
        for threads in [1, 2, 8] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            for run in 0..4 {
                let got = pool.install(|| forward_backward(map, x, w, g, c, &device));
                for (what, (a, b)) in ["output", "feature gradient", "weight gradient"].iter().zip(got.iter().zip(&reference)) {
                    let differing = count_differing(a, b);
                    assert_eq!(differing, 0, "{device:?}: {what} differs in {differing} values at {threads} threads, run {run}");
                }
            }
        }
    }
}

#[test]
fn wgpu_results_are_identical_run_to_run() {
    let Some(device) = wgpu_device() else { return };
    let (map, x, w, g, c) = dense_case();
    let reference = forward_backward(&map, &x, &w, &g, c, &device);
    let flex = forward_backward(&map, &x, &w, &g, c, &Device::flex());
    for (what, (a, b)) in ["output", "feature gradient", "weight gradient"].iter().zip(reference.iter().zip(&flex)) {
        assert_close(a, b, 1e-5, &format!("wgpu vs flex: {what}"));
    }
    for run in 0..4 {
        let got = forward_backward(&map, &x, &w, &g, c, &device);
        for (what, (a, b)) in ["output", "feature gradient", "weight gradient"].iter().zip(got.iter().zip(&reference)) {
            let differing = count_differing(a, b);
            assert_eq!(differing, 0, "wgpu: {what} differs in {differing} values on run {run}");
        }
    }
}
