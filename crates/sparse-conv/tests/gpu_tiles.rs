//! The GPU gather's tiled kernel, which a launch takes only past
//! `KernelOptions::gpu_tiled_min_cubes` tiles (more than these small cases have), forced on for
//! every launch of this process: the same cases as `backends.rs` agree across backends with it,
//! deferred maps included (their tile plans come from host tables built for them).

use sparse_conv::KernelOptions;

mod common;

#[test]
fn tiled_gather_agrees_with_the_cpu_backends() {
    // This binary's only test: the option holds for every launch in it.
    KernelOptions { gpu_tiled_min_cubes: 0, ..Default::default() }.apply();
    common::backends_agree_on_random_cases();
    if common::wgpu_device().is_some() {
        // The tiled kernel ran: only it makes tile plans.
        assert!(sparse_conv::profile::KernelTimes::now().tile_plan_ms > 0.0, "no tile plan was made");
    }
}
