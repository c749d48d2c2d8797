//! The GPU gather's tiled kernel, which a launch takes only past
//! `KernelOptions::gpu_tiled_min_cubes` tiles (more than these small cases have), forced on for
//! every launch of this process: the same cases as `backends.rs` agree across backends with it,
//! with the tile plans made on the device (the default) and on the host (`gpu_maps = "host"`).

use std::sync::Arc;

use sparse_conv::profile::KernelTimes;
use sparse_conv::{GpuMaps, KernelMap, KernelOptions};

mod common;

#[test]
fn tiled_gather_agrees_with_the_cpu_backends() {
    // This binary's only test: the options hold for every launch in it.
    let tiled = KernelOptions { gpu_tiled_min_cubes: 0, ..Default::default() };
    tiled.apply();
    common::backends_agree_on_random_cases();
    let Some(wgpu) = common::wgpu_device() else { return };
    // The tiled kernel ran: only it makes tile plans.
    assert!(KernelTimes::now().tile_plan_ms > 0.0, "no tile plan was made");

    // A deferred map's forward and both gradients through the tiled kernel read no host table:
    // its tables, pairs and tile plans are all made on the device.
    let mut r = common::rng(5);
    let coords = common::random_coords(&mut r, 3000, 2, 16, 1);
    let map = Arc::new(KernelMap::submanifold_deferred(Arc::new(sparse_conv::LevelCoords::on_host(coords.into())), 3, 1));
    let c = [8, 16];
    let (x, w, g) = (common::random_values(&mut r, map.n_in() * c[0]), common::random_values(&mut r, map.volume() * c[0] * c[1]), common::random_values(&mut r, map.n_out() * c[1]));
    let on_gpu = common::conv_outputs(&map, &x, &w, &g, c, &wgpu);
    assert!(!map.has_host_tables(), "the tiled gather built the deferred map's host tables");
    #[allow(deprecated)]
    let on_cpu = common::conv_outputs(&map, &x, &w, &g, c, &sparse_conv::burn::tensor::Device::flex());
    common::assert_close(&on_gpu.out, &on_cpu.out, 1e-5, "tiled deferred output");
    common::assert_close(&on_gpu.gx, &on_cpu.gx, 1e-5, "tiled deferred feature gradient");
    common::assert_close(&on_gpu.gw, &on_cpu.gw, 1e-5, "tiled deferred weight gradient");

    // The same for a down-sampling map a GPU tensor made on the device, and its transposed map.
    let coords = common::random_coords(&mut r, 3000, 2, 16, 1);
    let features = common::tensor2(&common::random_values(&mut r, coords.len() * 4), [coords.len(), 4], &wgpu, sparse_conv::burn::tensor::DType::F32);
    let input = sparse_conv::SparseTensor::new(features, coords).unwrap();
    input.prepare_down_levels([2]);
    let down = input.down_map(2).0;
    let up = Arc::new(KernelMap::transpose_of(&down));
    for (what, map) in [("down", &down), ("up", &up)] {
        let c = [8, 16];
        let (x, w, g) = (common::random_values(&mut r, map.n_in() * c[0]), common::random_values(&mut r, map.volume() * c[0] * c[1]), common::random_values(&mut r, map.n_out() * c[1]));
        let on_gpu = common::conv_outputs(map, &x, &w, &g, c, &wgpu);
        assert!(!map.has_host_tables(), "the tiled gather built the device {what} map's host tables");
        #[allow(deprecated)]
        let on_cpu = common::conv_outputs(map, &x, &w, &g, c, &sparse_conv::burn::tensor::Device::flex());
        common::assert_close(&on_gpu.out, &on_cpu.out, 1e-5, &format!("tiled device {what}: output"));
        common::assert_close(&on_gpu.gx, &on_cpu.gx, 1e-5, &format!("tiled device {what}: feature gradient"));
        common::assert_close(&on_gpu.gw, &on_cpu.gw, 1e-5, &format!("tiled device {what}: weight gradient"));
    }

    // The host's plans, as `gpu_maps = "host"` makes them.
    KernelOptions { gpu_maps: GpuMaps::Host, ..tiled }.apply();
    common::backends_agree_on_random_cases();
}
