//! The GPU gather's tiled kernel, which a launch takes only past `PMUNET_GPU_TILED_MIN_CUBES`
//! tiles (more than these small cases have), forced on for every launch of this process: the
//! same cases as `backends.rs` agree across backends with it.

mod common;

#[test]
fn tiled_gather_agrees_with_the_cpu_backends() {
    // SAFETY: this binary's only test sets the variable before any thread reads it (the GPU
    // module reads it once, at the first launch).
    unsafe { std::env::set_var("PMUNET_GPU_TILED_MIN_CUBES", "0") };
    common::backends_agree_on_random_cases();
}
