//! A trained detector loaded once from a run folder and applied to point clouds: the one
//! inference path `infer` (and, through it, every scoring of a checkpoint) goes through.
//!
//! ```no_run
//! use train::{RunDetector, Slot};
//! let detector = RunDetector::load("weights/person_minkunet".as_ref(), Slot::Latest, None)?;
//! // x forward, y left, z up, metres, JRDB's base frame (the floor near z = −0.7 m).
//! let points: Vec<[f32; 3]> = vec![[3.0, 0.5, 0.2], [3.1, 0.5, 0.4]];
//! let found = detector.detect(&points);
//! for (b, score) in found.boxes.iter().zip(&found.scores) {
//!     println!("{score:.2} at ({:.2}, {:.2}, {:.2}), heading {:.2} rad", b.cx, b.cy, b.cz, b.rot_z);
//! }
//! # Ok::<(), anyhow::Error>(())
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use burn::module::Module;
use burn::tensor::Device;
use data_jrdb::{Batch, Frame, collate, prepare};
use model::{CenterPoint, Detections, Detector, FacingClassifier, ModelConfig, PersonMinkUNet};
use rand::SeedableRng;

use crate::backend::{BackendKind, init_threads};
use crate::checkpoint::{Checkpoints, Slot};
use crate::config::RunConfig;
use crate::facing::load_facing;
use crate::run_dir::RunDir;

/// Either trained model, in inference mode.
enum Model {
    PersonMinkunet(PersonMinkUNet),
    Centerpoint(CenterPoint),
}

/// A run's model with its weights, its voxelization and its post-processing (the checkpoint's
/// facing stage included), on one device.
pub struct RunDetector {
    model: Model,
    config: RunConfig,
    device: Device,
    checkpoint: PathBuf,
    facing: Option<FacingClassifier>,
}

impl RunDetector {
    /// Loads `run`'s resolved config and the checkpoint in `slot` onto the run's backend (or
    /// `backend`), sizing the CPU thread pool and the kernels as the config says.
    pub fn load(run: &Path, slot: Slot, backend: Option<BackendKind>) -> Result<Self> {
        let config = RunDir::at(run).config().with_context(|| format!("{} is not a run folder", run.display()))?;
        Self::with_config(run, config, slot, backend)
    }

    /// As [`load`](Self::load) with `config` instead of the run's own (e.g. other
    /// post-processing); the model's shape must be the one the checkpoint holds.
    pub fn with_config(run: &Path, mut config: RunConfig, slot: Slot, backend: Option<BackendKind>) -> Result<Self> {
        if let Some(b) = backend {
            config.backend = b;
        }
        init_threads(config.threads)?;
        config.kernels.apply();
        let files = Checkpoints::new(RunDir::at(run).checkpoints())
            .get(slot)?
            .with_context(|| format!("{} has no `{slot}` checkpoint (--checkpoint latest or best)", run.display()))?;
        let device = config.backend.device()?;
        let model = match &config.model {
            ModelConfig::PersonMinkunet(c) => Model::PersonMinkunet(files.load_model(c.init(&device))?.valid()),
            ModelConfig::Centerpoint(c) => Model::Centerpoint(files.load_model(c.init(&device))?.valid()),
        };
        let facing = if config.model.post().facing_stage { load_facing(&files.dir)? } else { None };
        Ok(Self { model, config, device, checkpoint: files.dir, facing })
    }

    /// The resolved config the detector runs with.
    pub fn config(&self) -> &RunConfig {
        &self.config
    }

    /// The checkpoint folder its weights came from.
    pub fn checkpoint(&self) -> &Path {
        &self.checkpoint
    }

    /// The facing stage it applies (the checkpoint's `facing.json`, unless
    /// `model.post.facing_stage` is off).
    pub fn facing(&self) -> Option<&FacingClassifier> {
        self.facing.as_ref()
    }

    /// The device it runs on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// People in one cloud of points in JRDB's base frame (metres; x forward, y left, z up),
    /// best first: voxelized as the run was trained, detected, post-processed.
    pub fn detect(&self, points: &[[f32; 3]]) -> Detections {
        let frame = Frame {
            sequence: String::new(),
            name: String::new(),
            points: points.to_vec(),
            n_upper: points.len(),
            dropped_non_finite: 0,
            boxes: Vec::new(),
            num_points: Vec::new(),
            label_ids: Vec::new(),
            ignored: Vec::new(),
        };
        // Evaluation samples draw nothing at random (no augmentation, no cap).
        let sample = prepare(frame, &self.config.data.eval_sample(), &mut rand_chacha::ChaCha8Rng::seed_from_u64(0));
        let batch = collate(vec![sample], self.config.data.voxel_size);
        self.detect_batch(&batch).pop().unwrap_or_default()
    }

    /// Detections for every sample of a batch prepared as [`DataConfig::eval_sample`] says. The
    /// facing stage reads each sample's points (`Batch::clouds`); a batch made without them
    /// (training samples, a hand-made batch) keeps the network's directions.
    ///
    /// [`DataConfig::eval_sample`]: data_jrdb::DataConfig::eval_sample
    pub fn detect_batch(&self, batch: &Batch) -> Vec<Detections> {
        let mut found = match &self.model {
            Model::PersonMinkunet(m) => m.detect(batch, &self.device),
            Model::Centerpoint(m) => m.detect(batch, &self.device),
        };
        if let Some(stage) = &self.facing {
            for (d, cloud) in found.iter_mut().zip(&batch.clouds) {
                stage.orient_all(cloud, &mut d.boxes);
            }
        }
        found
    }
}
