//! From a `Frame` to a `Sample` (augment → voxelize → cap) and from samples to a `Batch`.

use rand::Rng;

use crate::augment::{AugmentConfig, Augmentation, perturb_points};
use crate::box3d::Box3d;
use crate::dataset::Frame;
use crate::volume::Volume;
use crate::voxelize::{VoxelConfig, Voxels, voxel_centre, voxelize};

/// How one frame becomes a sample.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SampleConfig {
    /// Points outside are dropped first.
    pub volume: Volume,
    /// Voxel size and pooling.
    pub voxel: VoxelConfig,
    /// Augmentation, `None` at evaluation.
    pub augment: Option<AugmentConfig>,
    /// Voxel cap (30,000 in training), `None` at evaluation.
    pub max_voxels: Option<usize>,
    /// Keep the frame's points in the sample (evaluation): what a second stage reads in a box.
    pub keep_points: bool,
}

impl Default for SampleConfig {
    /// The training settings of the paper.
    fn default() -> Self {
        Self { volume: Volume::default(), voxel: VoxelConfig::default(), augment: Some(AugmentConfig::default()), max_voxels: Some(30_000), keep_points: false }
    }
}

impl SampleConfig {
    /// Evaluation settings: no augmentation, no cap, the points kept.
    pub fn eval() -> Self {
        Self { volume: Volume::default(), voxel: VoxelConfig::default(), augment: None, max_voxels: None, keep_points: true }
    }
}

/// One frame, voxelized, with its (augmented) boxes.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Sequence name.
    pub sequence: String,
    /// Frame name (`000123`).
    pub name: String,
    /// The voxels.
    pub voxels: Voxels,
    /// Boxes, transformed like the points.
    pub boxes: Vec<Box3d>,
    /// `num_points` of each box (evaluation filters on it).
    pub num_points: Vec<i64>,
    /// Boxes the evaluator ignores, transformed like the points (not trained on).
    pub ignored: Vec<Box3d>,
    /// Points in the frame before voxelization (inside the volume).
    pub n_points: usize,
    /// Points dropped for lying outside the volume.
    pub dropped_out_of_volume: usize,
    /// The (augmented) points themselves when [`SampleConfig::keep_points`], else empty.
    pub points: Vec<[f32; 3]>,
    /// The transform applied, if any.
    pub augmentation: Option<Augmentation>,
}

/// Crops to the volume, augments, voxelizes and caps one frame.
pub fn prepare<R: Rng + ?Sized>(mut frame: Frame, cfg: &SampleConfig, rng: &mut R) -> Sample {
    let dropped_out_of_volume = cfg.volume.crop(&mut frame.points);
    let augmentation = cfg.augment.map(|a| {
        let t = Augmentation::sample(&a, rng);
        t.apply_points(&mut frame.points);
        perturb_points(&a, &mut frame.points, rng);
        frame.boxes = frame.boxes.iter().map(|b| t.apply_box(b)).collect();
        frame.ignored = frame.ignored.iter().map(|b| t.apply_box(b)).collect();
        t
    });
    let mut voxels = voxelize(&frame.points, &cfg.voxel);
    if let Some(max) = cfg.max_voxels {
        voxels = voxels.subsample(max, rng);
    }
    Sample {
        sequence: frame.sequence,
        name: frame.name,
        voxels,
        boxes: frame.boxes,
        num_points: frame.num_points,
        ignored: frame.ignored,
        n_points: frame.points.len(),
        dropped_out_of_volume,
        points: if cfg.keep_points { frame.points } else { Vec::new() },
        augmentation,
    }
}

/// A batch as plain arrays, ready to become tensors.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Batch {
    /// Voxel coordinates `(b, x, y, z)`, M rows, sample by sample.
    pub coords: Vec<[i32; 4]>,
    /// Features, M×3 row-major (raw xyz in metres).
    pub features: Vec<f32>,
    /// Voxel centres in metres, M×3 row-major (the regression reference).
    pub centres: Vec<f32>,
    /// Sample b owns rows `offsets[b]..offsets[b + 1]`; `offsets.len() == batch size + 1`.
    pub offsets: Vec<usize>,
    /// Boxes of each sample.
    pub boxes: Vec<Vec<Box3d>>,
    /// `num_points` of each box of each sample.
    pub num_points: Vec<Vec<i64>>,
    /// Each sample's boxes the evaluator ignores.
    pub ignored: Vec<Vec<Box3d>>,
    /// `(sequence, frame name)` of each sample.
    pub frames: Vec<(String, String)>,
    /// Voxel size used, metres.
    pub voxel_size: [f32; 3],
    /// Each sample's points before voxelization (empty unless kept: evaluation samples).
    pub clouds: Vec<Vec<[f32; 3]>>,
}

impl Batch {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether it has no samples.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Total voxels M.
    pub fn num_voxels(&self) -> usize {
        self.coords.len()
    }

    /// The feature (the voxel's point, metres) of voxel `row`.
    pub fn point(&self, row: usize) -> [f32; 3] {
        [0, 1, 2].map(|k| self.features[3 * row + k])
    }

    /// The centre (metres) of voxel `row`: what its box offsets are relative to.
    pub fn centre(&self, row: usize) -> [f32; 3] {
        [0, 1, 2].map(|k| self.centres[3 * row + k])
    }

    /// The voxel rows of sample `b`.
    pub fn rows(&self, b: usize) -> std::ops::Range<usize> {
        self.offsets[b]..self.offsets[b + 1]
    }

    /// The points (voxel features) of sample `b`.
    pub fn points(&self, b: usize) -> Vec<[f32; 3]> {
        self.rows(b).map(|r| self.point(r)).collect()
    }

    /// The batch cut into at most `parts` batches of consecutive samples, as even as they go (the
    /// first ones take one more), none empty (an empty batch stays one): what [`collate`] makes of
    /// each part's samples, for data-parallel training (one part a device).
    pub fn split(&self, parts: usize) -> Vec<Batch> {
        let n = self.len();
        if n == 0 {
            return vec![self.clone()];
        }
        let parts = parts.clamp(1, n);
        let mut out = Vec::with_capacity(parts);
        let mut first = 0;
        for p in 0..parts {
            let end = first + n / parts + usize::from(p < n % parts);
            let rows = self.offsets[first]..self.offsets[end];
            let coord = |c: &[i32; 4]| [c[0] - first as i32, c[1], c[2], c[3]];
            out.push(Batch {
                coords: self.coords[rows.clone()].iter().map(coord).collect(),
                features: self.features[3 * rows.start..3 * rows.end].to_vec(),
                centres: self.centres[3 * rows.start..3 * rows.end].to_vec(),
                offsets: self.offsets[first..=end].iter().map(|o| o - rows.start).collect(),
                boxes: self.boxes[first..end].to_vec(),
                num_points: self.num_points[first..end].to_vec(),
                ignored: self.ignored[first..end].to_vec(),
                frames: self.frames[first..end].to_vec(),
                voxel_size: self.voxel_size,
                clouds: self.clouds[first..end].to_vec(),
            });
            first = end;
        }
        out
    }
}

/// Stacks samples into one batch; the batch index is each sample's position.
pub fn collate(samples: Vec<Sample>, voxel_size: [f32; 3]) -> Batch {
    let m: usize = samples.iter().map(|s| s.voxels.len()).sum();
    let mut b = Batch {
        coords: Vec::with_capacity(m),
        features: Vec::with_capacity(3 * m),
        centres: Vec::with_capacity(3 * m),
        offsets: vec![0],
        voxel_size,
        ..Default::default()
    };
    for (i, s) in samples.into_iter().enumerate() {
        for (c, f) in s.voxels.coords.iter().zip(&s.voxels.features) {
            b.coords.push([i as i32, c[0], c[1], c[2]]);
            b.features.extend_from_slice(f);
            b.centres.extend_from_slice(&voxel_centre(*c, voxel_size));
        }
        b.offsets.push(b.coords.len());
        b.boxes.push(s.boxes);
        b.num_points.push(s.num_points);
        b.ignored.push(s.ignored);
        b.frames.push((s.sequence, s.name));
        b.clouds.push(s.points);
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample of `voxels` voxels with one box, named by `i`.
    fn sample(i: usize, voxels: usize) -> Sample {
        let coords: Vec<[i32; 3]> = (0..voxels as i32).map(|v| [v + i as i32, 2 * v, -v]).collect();
        Sample {
            sequence: format!("seq-{i}"),
            name: format!("{i:06}"),
            voxels: Voxels { features: coords.iter().map(|c| c.map(|x| x as f32 * 0.2 + 0.05)).collect(), counts: vec![1; voxels], coords },
            boxes: vec![Box3d { cx: i as f64, cy: 0.0, cz: 0.0, l: 0.5, w: 0.5, h: 1.7, rot_z: 0.0 }],
            num_points: vec![voxels as i64],
            ignored: vec![],
            n_points: voxels,
            dropped_out_of_volume: 0,
            points: (0..voxels).map(|v| [v as f32, i as f32, 0.0]).collect(),
            augmentation: None,
        }
    }

    #[test]
    fn prepare_applies_the_perturbations_and_nothing_when_they_are_off() {
        use rand::SeedableRng;
        let frame = || Frame {
            sequence: "s".into(),
            name: "000000".into(),
            points: (0..4000).map(|i| [(i % 40) as f32 * 0.25 - 5.0, (i / 40) as f32 * 0.1 - 5.0, -0.5]).collect(),
            n_upper: 4000,
            dropped_non_finite: 0,
            boxes: vec![Box3d { cx: 1.0, cy: 1.0, cz: 0.2, l: 0.5, w: 0.5, h: 1.7, rot_z: 0.0 }],
            num_points: vec![10],
            label_ids: vec!["p".into()],
            ignored: vec![],
        };
        let cfg = |augment| SampleConfig { augment: Some(augment), keep_points: true, max_voxels: None, ..SampleConfig::default() };
        let run = |augment| prepare(frame(), &cfg(augment), &mut rand_chacha::ChaCha8Rng::seed_from_u64(1));
        let plain = run(AugmentConfig::default());
        assert_eq!(plain.points.len(), 4000);
        let turned = plain.augmentation.unwrap();
        let moved = run(AugmentConfig { translate: [0.5, 0.5, 0.1], ..AugmentConfig::default() });
        let t = moved.augmentation.unwrap().translation;
        assert!(t.iter().all(|v| *v != 0.0), "{t:?}");
        // Same scale and turn (drawn first), then moved by t: points and the box alike.
        assert_eq!((moved.augmentation.unwrap().scale, moved.augmentation.unwrap().angle), (turned.scale, turned.angle));
        for (p, q) in plain.points.iter().zip(&moved.points) {
            assert!((0..3).all(|k| ((q[k] - p[k]) as f64 - t[k]).abs() < 1e-5));
        }
        assert!((moved.boxes[0].cx - plain.boxes[0].cx - t[0]).abs() < 1e-12 && (moved.boxes[0].cz - plain.boxes[0].cz - t[2]).abs() < 1e-12);
        let dropped = run(AugmentConfig { drop: 0.5, jitter: 0.01, ..AugmentConfig::default() });
        assert!(dropped.points.len() < 4000 && dropped.n_points == dropped.points.len(), "{}", dropped.points.len());
        assert_eq!(dropped.boxes, plain.boxes);
    }

    #[test]
    fn split_parts_are_the_collated_parts() {
        let vs = [0.2, 0.2, 0.2];
        let samples: Vec<Sample> = [3, 5, 1, 4, 2].iter().enumerate().map(|(i, &v)| sample(i, v)).collect();
        let whole = collate(samples.clone(), vs);
        for parts in 1..=7 {
            let split = whole.split(parts);
            let sizes: Vec<usize> = split.iter().map(Batch::len).collect();
            let expected_parts = parts.min(5);
            assert_eq!(split.len(), expected_parts, "{parts} parts");
            assert!(sizes.iter().max().unwrap() - sizes.iter().min().unwrap() <= 1, "{parts} parts: {sizes:?}");
            let mut first = 0;
            for part in &split {
                let expected = collate(samples[first..first + part.len()].to_vec(), vs);
                assert_eq!(part, &expected, "{parts} parts, samples from {first}");
                first += part.len();
            }
            assert_eq!(first, 5);
        }
        assert_eq!(Batch::default().split(3), vec![Batch::default()]);
    }
}
