//! Every CPU kernel choice of `KernelOptions` gives the f64 composition's outputs and gradients in
//! f32, the SIMD levels each other's bits, and the choice holds until changed; so do the GPU's. Its own test binary: the options are process-wide, and
//! the thread-count tests elsewhere compare bits within one choice.

mod common;

use std::sync::Arc;

use common::*;
use sparse_conv::burn::tensor::{DType, Device};
use sparse_conv::{CoordIndex, CpuKernels, GpuMaps, KernelMap, KernelOptions};

#[test]
fn every_cpu_kernel_choice_matches_the_f64_result() {
    let mut r = rng(5);
    let c = [24, 40];
    let coords = random_coords(&mut r, 3_000, 2, 20, 1);
    let index = CoordIndex::build(&coords).unwrap();
    let map = Arc::new(KernelMap::submanifold(&coords, &index, 3, 1));
    let x = random_values(&mut r, map.n_in() * c[0]);
    let w = random_values(&mut r, map.volume() * c[0] * c[1]);
    let g = random_values(&mut r, map.n_out() * c[1]);
    // f64 runs the general path whatever the options say: the reference.
    let reference = conv_outputs_in(&map, &x, &w, &g, c, &Device::flex(), DType::F64);
    let mut outputs = Vec::new();
    let mut paths = Vec::new();
    for cpu in [CpuKernels::Generic, CpuKernels::Auto, CpuKernels::Avx2] {
        KernelOptions { cpu, ..Default::default() }.apply();
        assert_eq!(KernelOptions::current().cpu, cpu);
        paths.push(sparse_conv::cpu_kernel_path());
        let got = conv_outputs_in(&map, &x, &w, &g, c, &Device::flex(), DType::F32);
        for (name, a, b) in [("output", &got.out, &reference.out), ("input gradient", &got.gx, &reference.gx), ("weight gradient", &got.gw, &reference.gw)] {
            assert_close(a, b, 1e-5, &format!("{cpu:?} {name}"));
        }
        outputs.push([got.out, got.gx, got.gw].concat());
    }
    let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(a, b)| a.to_bits() == b.to_bits());
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // A SIMD kernel ran (its sums round differently from the general path's), so the choice
        // took effect; AVX-512 and AVX2 sum every element's terms in the same order.
        assert_eq!(paths[2], "AVX2+FMA micro-kernels");
        assert!(!same(&outputs[0], &outputs[2]), "generic and AVX2 results (output and both gradients) are the same bits");
        assert!(same(&outputs[1], &outputs[2]), "{} and {} results differ", paths[1], paths[2]);
    }
    println!("paths: {paths:?}");
    KernelOptions { gpu_tiled_min_cubes: 0, ..Default::default() }.apply();
    assert_eq!(KernelOptions::current(), KernelOptions { cpu: CpuKernels::Auto, gpu_tiled_min_cubes: 0, gpu_maps: GpuMaps::Device });
    // Where a GPU tensor's submanifold maps are built follows the option.
    for gpu_maps in [GpuMaps::Host, GpuMaps::Device] {
        KernelOptions { gpu_maps, ..Default::default() }.apply();
        assert_eq!(KernelOptions::current().gpu_maps, gpu_maps);
        if let Some(device) = wgpu_device() {
            let features = sparse_conv::burn::tensor::Tensor::<2>::ones([coords.len(), 2], &device);
            let map = sparse_conv::SparseTensor::new(features, coords.clone()).unwrap().submanifold_map(3);
            assert_eq!(map.has_host_tables(), gpu_maps == GpuMaps::Host, "{gpu_maps:?}");
        }
    }
}
