//! The `[data]` settings of a run: where the tree is, which frames form each split, and how a
//! frame becomes a sample. The runner embeds this table as it is; every default is the authors'.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::augment::AugmentConfig;
use crate::batch::SampleConfig;
use crate::dataset::{DatasetConfig, DatasetFormat, OnBadFrame};
use crate::kitti::KittiOptions;
use crate::nuscenes::NuscenesOptions;
use crate::pcd::NonFinite;
use crate::sim::SimulateConfig;
use crate::split::{DEFAULT_VAL_SEQUENCES, Split};
use crate::volume::Volume;
use crate::voxelize::{Pooling, VoxelConfig};

/// Where the data is and how frames become samples (docs/data.md, docs/model.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DataConfig {
    /// The dataset's layout: `jrdb` (default), `kitti` or `nuscenes` (docs/data.md).
    pub format: DatasetFormat,
    /// The dataset: a JRDB-format tree (a plain root or a folder holding
    /// `train_dataset_with_activity/`), a KITTI object root or a nuScenes-style root.
    /// A relative path is relative to the working directory.
    pub root: PathBuf,
    /// KITTI's settings (`format = "kitti"`).
    #[serde(skip_serializing_if = "is_default")]
    pub kitti: KittiOptions,
    /// nuScenes' settings (`format = "nuscenes"`).
    #[serde(skip_serializing_if = "is_default")]
    pub nuscenes: NuscenesOptions,
    /// If present and `root` does not exist, a simulated tree is generated there first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub simulate: Option<SimulateConfig>,
    /// Split trained on.
    pub train_split: Split,
    /// Split validated on.
    pub val_split: Split,
    /// The validation sequences (default: JRDB's 7 suggested ones, docs/data.md); an entry ending
    /// in `*` matches every sequence that starts with what precedes it (`sim-val-*` for a simulated
    /// benchmark).
    pub val_sequences: Vec<String>,
    /// The working volume (metres, base frame): points outside are dropped before voxelization.
    pub volume: Volume,
    /// Voxel size in metres (x, y, z).
    pub voxel_size: [f32; 3],
    /// A voxel's feature: the first point's xyz (the authors') or the mean.
    pub pooling: Pooling,
    /// Training voxel cap per frame (30,000), drawn at random; 0: no cap. Evaluation never caps,
    /// so a cap trains on sparser frames than it is scored on.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_voxels: Option<usize>,
    /// Training augmentation (the authors' scale and rotation).
    pub augment: AugmentSection,
    /// Unreadable frames: `fail` or `skip` with a warning.
    pub on_bad_frame: OnBadFrame,
    /// Prepare the next training batch on a second thread.
    pub prefetch: bool,
    /// More trees whose training split is trained on beside `root`'s (`[[data.also_train]]`),
    /// each generated on first use from its own `simulate`; validation stays on `root`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub also_train: Vec<ExtraTree>,
}

/// A tree trained on beside `data.root`: its training split (the same `val_sequences` left
/// out) is appended to the root's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtraTree {
    /// The tree (as `data.root`).
    pub root: PathBuf,
    /// Generated there first when `root` does not exist (as `data.simulate`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulate: Option<SimulateConfig>,
}

impl Default for DataConfig {
    fn default() -> Self {
        Self {
            format: DatasetFormat::Jrdb,
            root: PathBuf::from("data/jrdb"),
            kitti: KittiOptions::default(),
            nuscenes: NuscenesOptions::default(),
            simulate: None,
            train_split: Split::Train,
            val_split: Split::Val,
            val_sequences: DEFAULT_VAL_SEQUENCES.map(String::from).to_vec(),
            volume: Volume::default(),
            voxel_size: [0.05, 0.05, 0.1],
            pooling: Pooling::First,
            max_voxels: Some(30_000),
            augment: AugmentSection::default(),
            on_bad_frame: OnBadFrame::Fail,
            prefetch: true,
            also_train: Vec::new(),
        }
    }
}

impl DataConfig {
    /// Per-frame processing of training samples.
    pub fn train_sample(&self) -> SampleConfig {
        SampleConfig {
            volume: self.volume,
            voxel: VoxelConfig { voxel_size: self.voxel_size, pooling: self.pooling },
            augment: self.augment.enabled.then_some(self.augment.to_config()),
            max_voxels: self.max_voxels.filter(|&m| m > 0),
            keep_points: false,
        }
    }

    /// Per-frame processing at evaluation: no augmentation, no cap, the points kept.
    pub fn eval_sample(&self) -> SampleConfig {
        SampleConfig {
            volume: self.volume,
            voxel: VoxelConfig { voxel_size: self.voxel_size, pooling: self.pooling },
            augment: None,
            max_voxels: None,
            keep_points: true,
        }
    }

    /// What opening `split` of the tree needs: the validation sequences, labels required,
    /// non-finite points dropped.
    pub fn dataset(&self, split: Split) -> DatasetConfig {
        DatasetConfig {
            format: self.format,
            kitti: self.kitti,
            nuscenes: self.nuscenes.clone(),
            split,
            val_sequences: self.val_sequences.clone(),
            sequences: None,
            non_finite: NonFinite::Drop,
            on_bad_frame: self.on_bad_frame,
            require_labels: true,
        }
    }
}

fn is_default<T: Default + PartialEq>(v: &T) -> bool {
    *v == T::default()
}

/// Training augmentation: `p ↦ s·R(α)·p + t`, `s ~ U(scale)`, `α ~ U(0, 2π)` (the authors'), `t`
/// and the point perturbations off unless set (`augment::AugmentConfig`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AugmentSection {
    /// Augment at all.
    pub enabled: bool,
    /// Range of the scale factor.
    pub scale: [f64; 2],
    /// Random rotation about z.
    pub rotate: bool,
    /// Half-ranges of a random translation in x, y, z (m).
    pub translate: [f64; 3],
    /// Standard deviation of each point's random displacement (m).
    pub jitter: f64,
    /// Largest fraction of a frame's points dropped at random.
    pub drop: f64,
}

impl Default for AugmentSection {
    fn default() -> Self {
        let a = AugmentConfig::default();
        Self { enabled: true, scale: a.scale, rotate: a.rotate, translate: a.translate, jitter: a.jitter, drop: a.drop }
    }
}

impl AugmentSection {
    /// The ranges sampling needs: finite, a positive scale range in order, the rest ≥ 0, `drop` < 1.
    pub fn validate(&self) -> Result<(), String> {
        let [lo, hi] = self.scale;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return Err(format!("data.augment.scale must be two finite positive numbers, lowest first, got {:?}", self.scale));
        }
        if self.translate.iter().any(|h| !(h.is_finite() && *h >= 0.0)) {
            return Err(format!("data.augment.translate must be three finite half-ranges ≥ 0 (metres), got {:?}", self.translate));
        }
        if !(self.jitter.is_finite() && self.jitter >= 0.0) {
            return Err(format!("data.augment.jitter must be a finite standard deviation ≥ 0 (metres), got {}", self.jitter));
        }
        if !(0.0..1.0).contains(&self.drop) {
            return Err(format!("data.augment.drop must be a fraction in [0, 1), got {}", self.drop));
        }
        Ok(())
    }

    fn to_config(self) -> AugmentConfig {
        AugmentConfig { scale: self.scale, rotate: self.rotate, translate: self.translate, jitter: self.jitter, drop: self.drop }
    }
}
