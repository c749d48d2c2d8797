//! The dense baseline end to end: shapes, overfitting a few simulated frames (loss and AP@0.3),
//! and a checkpoint round trip.

mod common;

use common::{ap03, head_tail, sim_batch, train, valid_gt};
use model::{CenterPointConfig, Detector};
use sparse_conv::burn::module::Module;
use sparse_conv::burn::tensor::Device;

fn small() -> CenterPointConfig {
    CenterPointConfig {
        x_range: [-4.8, 4.8],
        y_range: [-4.8, 4.8],
        layer_nums: vec![1, 2, 2],
        width: 0.25,
        // Running statistics must catch up within a test-sized run (CenterPoint's 0.01 would not).
        bn_momentum: 0.1,
        ..Default::default()
    }
}

#[test]
fn shapes_follow_the_grid() {
    let batch = sim_batch("cp-shapes", 2, 6, 4.5, 3);
    let device = Device::flex();
    let model = common::initialised(&device, None, || small().init(&device));
    assert_eq!(model.grid().size, [96, 96, 1]);
    assert_eq!(model.bev(&batch, &device).dims(), [2, 16, 96, 96]);
    assert_eq!(model.forward(&batch, &device).dims(), [2, 9, 48, 48]);
    // The heatmap bias starts every score near sigmoid(−2.19) ≈ 0.1.
    let out = model.head_output(&batch, &device);
    assert_eq!(out.len(), 2 * 9 * 48 * 48);
    // A config whose blocks do not meet at one resolution is refused.
    let bad = CenterPointConfig { up_strides: vec![1, 1, 4], ..small() };
    assert!(std::panic::catch_unwind(|| bad.init(&Device::flex())).is_err());
}

#[test]
fn overfits_simulated_frames_and_checkpoint_round_trips() {
    let batch = sim_batch("cp-fit", 2, 16, 4.5, 11);
    assert!(valid_gt(&batch) >= 3, "the crop holds people: {}", valid_gt(&batch));
    let device = Device::flex().autodiff();
    // Seeded initialisation: the test's outcome must not depend on the run.
    let model = common::initialised(&device, Some(7), || small().init(&device));
    let (model, losses) = train(model, &batch, &device, 60, 3e-3);
    let (first, last) = head_tail(&losses, 5);
    eprintln!("CenterPoint loss {first:.3} → {last:.3}");
    assert!(losses.iter().all(|l| l.is_finite()));
    assert!(last < first / 8.0, "loss falls a lot: {first} → {last}");
    let eval_device = Device::flex();
    let model = model.valid();
    let dets = model.detect(&batch, &eval_device);
    let ap = ap03(&batch, &dets);
    eprintln!("AP@0.3 on the training frames: {ap:.3} ({} GT)", valid_gt(&batch));
    assert!(ap > 0.85, "AP@0.3 {ap}");

    let path = std::env::temp_dir().join(format!("pmunet-cp-ckpt-{}", std::process::id()));
    model.clone().save_file(&path).unwrap();
    let fresh = small().init(&eval_device);
    assert_ne!(fresh.detect(&batch, &eval_device), dets);
    let loaded = fresh.load_file(&path);
    assert_eq!(loaded.detect(&batch, &eval_device), dets, "identical detections after a round trip");
    // Burn writes `<path>.bpk`.
    let _ = std::fs::remove_file(path.with_extension("bpk"));
}
