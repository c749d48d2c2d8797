//! Both detectors give the same outputs on flex and ndarray (and on wgpu when
//! `PMUNET_TEST_WGPU=1`, which needs a Vulkan adapter such as lavapipe), and train on each.

mod common;

use std::io::Write;

use common::sim_batch;
use model::{CenterPointConfig, Detector, PersonMinkUNetConfig};
use sparse_conv::burn::tensor::Device;

fn other_devices() -> Vec<(&'static str, Device)> {
    #[allow(deprecated)]
    let mut d = vec![("ndarray", Device::ndarray())];
    if std::env::var("PMUNET_TEST_WGPU").is_ok_and(|v| v == "1") {
        d.push(("wgpu", wgpu_device()));
    } else {
        // Straight to stderr: libtest hides `eprintln!` of a passing test.
        let _ = writeln!(std::io::stderr(), "wgpu not checked: set PMUNET_TEST_WGPU=1 where a Vulkan adapter exists");
    }
    d
}

/// The wgpu device on the platform's native API (never OpenGL, where the op's kernels hang),
/// initialised once per process by `sparse_conv::wgpu_device`.
fn wgpu_device() -> Device {
    sparse_conv::wgpu_device().unwrap_or_else(|e| panic!("PMUNET_TEST_WGPU=1 but {e}"))
}

fn assert_close(a: &[f32], b: &[f32], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    let scale = a.iter().fold(1f32, |m, x| m.max(x.abs()));
    let worst = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
    assert!(worst <= 1e-3 * scale, "{what}: largest difference {worst} (scale {scale})");
}

/// `make(device)` builds the model; the flex model's outputs are compared with the same weights
/// moved to each other backend, and a fresh model trains one step there.
fn check<M: Detector>(make: impl Fn(&Device) -> M, batch: &data_jrdb::Batch, name: &str) {
    let model = make(&Device::flex());
    let flex = Device::flex();
    let reference = model.head_output(batch, &flex);
    for (backend, device) in other_devices() {
        let moved = model.clone().to_device(&device);
        assert_close(&reference, &moved.head_output(batch, &device), &format!("{name} on {backend}"));
        let ad = device.clone().autodiff();
        let trainable = make(&ad);
        let loss = trainable.loss(batch, &ad);
        let grads = loss.total.backward();
        let g = sparse_conv::burn::optim::GradientsParams::from_grads(grads, &trainable);
        assert!(!g.is_empty(), "{name} on {backend}: gradients reach the parameters");
        assert!(!trainable.detect(batch, &ad).is_empty());
    }
}

#[test]
fn person_minkunet_matches_flex() {
    let batch = sim_batch("backends-pmu", 1, 6, 4.0, 2);
    let cfg = PersonMinkUNetConfig { width: 0.25, ..Default::default() };
    check(|d| cfg.init(d), &batch, "Person-MinkUNet");
}

#[test]
fn centerpoint_matches_flex() {
    let batch = sim_batch("backends-cp", 1, 6, 3.0, 2);
    let cfg = CenterPointConfig { x_range: [-3.2, 3.2], y_range: [-3.2, 3.2], layer_nums: vec![1, 1, 1], width: 0.25, ..Default::default() };
    check(|d| cfg.init(d), &batch, "CenterPoint");
}

/// On wgpu Person-MinkUNet's coarse levels stay on the device through a forward and backward
/// pass: nothing in the U-Net reads their coordinates or sizes back.
#[test]
fn person_minkunet_keeps_its_coarse_levels_on_a_gpu() {
    if !std::env::var("PMUNET_TEST_WGPU").is_ok_and(|v| v == "1") {
        return;
    }
    let batch = sim_batch("backends-pmu-levels", 1, 6, 4.0, 2);
    let cfg = PersonMinkUNetConfig { width: 0.25, ..Default::default() };
    let device = wgpu_device().autodiff();
    let model = cfg.init(&device);
    let input = model::PersonMinkUNet::input(&batch, cfg.input, &device);
    let before = sparse_conv::profile::KernelTimes::now();
    let levels = model.backbone.forward_levels(input);
    let out = levels.up.last().expect("the U-Net has up stages").features();
    let _ = (out.clone() * out).sum().backward();
    // The host counted every level's voxels: the op read nothing back.
    assert_eq!(sparse_conv::profile::KernelTimes::now().read_backs, before.read_backs, "the op read from the device");
    assert!(levels.down.len() > 2, "the U-Net has coarse levels");
    for (i, level) in levels.down.iter().enumerate().skip(1) {
        assert!(!level.level().is_on_host(), "down level {i}'s coordinates came to the host");
    }
}
