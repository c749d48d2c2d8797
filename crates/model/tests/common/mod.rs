//! Simulated frames, a short training loop and AP@0.3 for the model tests.
#![allow(dead_code)]

use data_jrdb::sim::{SynthConfig, synth};
use data_jrdb::{Batch, DatasetConfig, Dataset, SampleConfig, Split, collate, prepare};
use eval::ap::{Frame, Overlap, Protocol, evaluate};
use eval::kitti::KittiObject;
use model::{Detections, Detector};
use rand::SeedableRng;
use sparse_conv::burn::optim::{AdamConfig, GradientsParams};
use sparse_conv::burn::tensor::Device;

/// The model `init` builds, its weights drawn (with `seed`, from the backend's generator seeded
/// first) under a lock that every model of the test binary is built under: the generator is one
/// per process and tests run on parallel threads, so another test's draws in between would change
/// the seeded weights. Burn draws a parameter's weights when it is first read, not in `init`, so
/// they are read (through a record) before the lock is let go.
pub fn initialised<M: sparse_conv::burn::module::Module>(device: &Device, seed: Option<u64>, init: impl FnOnce() -> M) -> M {
    static RNG: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _rng = RNG.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(seed) = seed {
        device.seed(seed);
    }
    let model = init();
    let record = model.clone().into_record();
    model.load_record(record)
}

/// `frames` simulated frames (one sequence), points and boxes cropped to `radius` metres in BEV,
/// voxelized without augmentation, as one batch.
pub fn sim_batch(name: &str, frames: usize, max_people: usize, radius: f32, seed: u64) -> Batch {
    let root = std::env::temp_dir().join(format!("pmunet-model-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    synth(&root, &SynthConfig { sequences: 1, frames, seed, max_people, ..Default::default() }).unwrap();
    let ds = Dataset::open(&root, &DatasetConfig { split: Split::TrainVal, ..Default::default() }).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let samples = (0..ds.len())
        .map(|i| {
            let mut f = ds.load(i).unwrap();
            f.points.retain(|p| p[0].hypot(p[1]) < radius);
            let keep: Vec<bool> = f.boxes.iter().map(|b| (b.bev_range() as f32) < radius - 0.5).collect();
            let mut k = keep.iter();
            f.boxes.retain(|_| *k.next().unwrap());
            let mut k = keep.iter();
            f.num_points.retain(|_| *k.next().unwrap());
            prepare(f, &SampleConfig::eval(), &mut rng)
        })
        .collect();
    let _ = std::fs::remove_dir_all(&root);
    collate(samples, SampleConfig::eval().voxel.voxel_size)
}

/// Official-protocol AP at 3D IoU 0.3 of `dets` against the batch's boxes (recounted `num_points`
/// from the in-box voxels, so the ≥ 10 filter sees this crop).
///
/// The official AP samples precision at 40 recall steps from the true positives' scores, so with
/// fewer than 41 valid GT it cannot reach 1 (6 GT cap it at 5/40). The frames are therefore
/// evaluated as enough identical copies to hold at least 80 valid GT: precision and recall at
/// every threshold are those of the frames themselves.
pub fn ap03(batch: &Batch, dets: &[Detections]) -> f64 {
    let copies = 80usize.div_ceil(valid_gt(batch).max(1));
    let frames: Vec<Frame> = (0..batch.len() * copies)
        .map(|i| (i, i % batch.len()))
        .map(|(i, s)| (format!("{i:06}"), s))
        .map(|(name, s)| {
            let pts: Vec<[f32; 3]> = batch.points(s);
            Frame {
                sequence: "seq".into(),
                name,
                gt: batch.boxes[s].iter().map(|b| KittiObject::from_box3d(b, b.count_inside(&pts) as i32, 1.0)).collect(),
                det: dets[s].boxes.iter().zip(&dets[s].scores).map(|(b, &sc)| KittiObject::from_box3d(b, -1, sc as f64)).collect(),
            }
        })
        .collect();
    evaluate(&frames, 0.3, Overlap::Box3d, &Protocol::official()).ap
}

/// Valid GT (≥ 10 voxels) in the batch.
pub fn valid_gt(batch: &Batch) -> usize {
    (0..batch.len())
        .map(|s| {
            let pts: Vec<[f32; 3]> = batch.points(s);
            batch.boxes[s].iter().filter(|b| b.count_inside(&pts) >= 10).count()
        })
        .sum()
}

/// For every GT box with at least 10 points, the heading error (degrees, over 360°) of the
/// nearest detection (BEV centres) within 0.3 m; sorted.
pub fn heading_errors(batch: &Batch, dets: &[Detections]) -> Vec<f64> {
    let mut errors = Vec::new();
    for s in 0..batch.len() {
        let pts: Vec<[f32; 3]> = batch.points(s);
        for g in batch.boxes[s].iter().filter(|b| b.count_inside(&pts) >= 10) {
            let near = dets[s].boxes.iter().map(|d| ((d.cx - g.cx).hypot(d.cy - g.cy), d)).filter(|(r, _)| *r < 0.3);
            if let Some((_, d)) = near.min_by(|a, b| a.0.total_cmp(&b.0)) {
                let diff = (d.rot_z - g.rot_z).rem_euclid(std::f64::consts::TAU);
                errors.push(diff.min(std::f64::consts::TAU - diff).to_degrees());
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    errors
}

/// Trains `model` on `batch` for `steps` Adam steps at `lr`; returns it and the loss of every step.
pub fn train<M: Detector>(mut model: M, batch: &Batch, device: &Device, steps: usize, lr: f64) -> (M, Vec<f64>) {
    let mut optim = AdamConfig::new().init();
    let mut losses = Vec::with_capacity(steps);
    for _ in 0..steps {
        let terms = model.loss(batch, device);
        losses.push(terms.total.to_data().try_to_vec::<f32>().unwrap()[0] as f64);
        let grads = GradientsParams::from_grads(terms.total.backward(), &model);
        model = optim.step(lr, model, grads);
    }
    (model, losses)
}

/// Mean of the first and of the last `n` losses.
pub fn head_tail(losses: &[f64], n: usize) -> (f64, f64) {
    let n = n.min(losses.len());
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    (mean(&losses[..n]), mean(&losses[losses.len() - n..]))
}
