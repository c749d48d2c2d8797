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
use data_jrdb::{Batch, Box3d, Frame, collate, prepare};
use model::{CenterPoint, Detections, Detector, FacingClassifier, GridTurn, ModelConfig, PersonMinkUNet, focus, fuse, turned_batch};
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

/// A run's model with its weights, its voxelization and its post-processing (test-time turns and
/// the checkpoint's facing stage included), on one device.
pub struct RunDetector {
    model: Model,
    config: RunConfig,
    device: Device,
    checkpoint: PathBuf,
    facing: Option<FacingClassifier>,
    turns: Vec<GridTurn>,
}

impl RunDetector {
    /// Loads `run`'s resolved config and the checkpoint in `slot` onto the run's backend (or
    /// `backend`), sizing the CPU thread pool and the kernels as the config says.
    pub fn load(run: &Path, slot: Slot, backend: Option<BackendKind>) -> Result<Self> {
        let config = RunDir::at(run).config().with_context(|| format!("{} is not a run folder", run.display()))?;
        Self::with_config(run, config, slot, backend)
    }

    /// As [`load`](Self::load) with keys of the run's config overridden for this detector
    /// (`model.post.test_time_turns=4`, as `--set` of `detect` and `serve`); the run's
    /// `config.toml` is unchanged.
    pub fn load_with(run: &Path, overrides: &[String], slot: Slot, backend: Option<BackendKind>) -> Result<Self> {
        if overrides.is_empty() {
            return Self::load(run, slot, backend);
        }
        let config = RunDir::at(run).config_with(overrides).with_context(|| format!("{} with --set {}", run.display(), overrides.join(" --set ")))?;
        Self::with_config(run, config, slot, backend)
    }

    /// As [`load`](Self::load) with `config` instead of the run's own (e.g. other
    /// post-processing); the model's shape must be the one the checkpoint holds.
    pub fn with_config(run: &Path, mut config: RunConfig, slot: Slot, backend: Option<BackendKind>) -> Result<Self> {
        if let Some(b) = backend {
            config.backend = b;
        }
        let turns = GridTurn::passes(config.model.post().test_time_turns).map_err(anyhow::Error::msg)?;
        init_threads(config.threads)?;
        config.kernels.apply();
        let files = Checkpoints::new(RunDir::at(run).checkpoints())
            .get(slot)?
            .with_context(|| format!("{} has no `{slot}` checkpoint (--checkpoint latest or best)", run.display()))?;
        let device = config.backend.device()?;
        let model = match &config.model {
            // Quarter-turn ties written out: the same function at a plain network's cost.
            ModelConfig::PersonMinkunet(c) => Model::PersonMinkunet(files.load_model(c.init(&device))?.valid().untied()),
            ModelConfig::Centerpoint(c) => Model::Centerpoint(files.load_model(c.init(&device))?.valid()),
        };
        let facing = if config.model.post().facing_stage { load_facing(&files.dir)? } else { None };
        Ok(Self { model, config, device, checkpoint: files.dir, facing, turns })
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
        let batch = self.batch_of(vec![(String::new(), String::new(), points.to_vec())]);
        self.detect_batch(&batch).pop().unwrap_or_default()
    }

    /// Clouds in the base frame, each with its `(sequence, frame name)`, as one evaluation batch.
    fn batch_of(&self, clouds: Vec<(String, String, Vec<[f32; 3]>)>) -> Batch {
        let cfg = self.config.data.eval_sample();
        let samples = clouds
            .into_iter()
            .map(|(sequence, name, points)| {
                let frame = Frame {
                    sequence,
                    name,
                    n_upper: points.len(),
                    points,
                    dropped_non_finite: 0,
                    boxes: Vec::new(),
                    num_points: Vec::new(),
                    label_ids: Vec::new(),
                    ignored: Vec::new(),
                };
                // Evaluation samples draw nothing at random (no augmentation, no cap).
                prepare(frame, &cfg, &mut rand_chacha::ChaCha8Rng::seed_from_u64(0))
            })
            .collect();
        collate(samples, self.config.data.voxel_size)
    }

    /// Detections for every sample of a batch prepared as [`DataConfig::eval_sample`] says. The
    /// facing stage reads each sample's points (`Batch::clouds`); a batch made without them
    /// (training samples, a hand-made batch) keeps the network's directions.
    ///
    /// [`DataConfig::eval_sample`]: data_jrdb::DataConfig::eval_sample
    pub fn detect_batch(&self, batch: &Batch) -> Vec<Detections> {
        let mut found = self.forward(batch);
        if self.turns.len() > 1 {
            found = self.fused_over_turns(batch, found);
        }
        if let Some(stage) = &self.facing {
            for (d, cloud) in found.iter_mut().zip(&batch.clouds) {
                stage.orient_all(cloud, &mut d.boxes);
            }
        }
        found
    }

    /// The network and its post-processing on one batch.
    fn forward(&self, batch: &Batch) -> Vec<Detections> {
        match &self.model {
            Model::PersonMinkunet(m) => m.detect(batch, &self.device),
            Model::Centerpoint(m) => m.detect(batch, &self.device),
        }
    }

    /// `first` (the detections in `batch` as it is) fused with those in its voxels at the other
    /// test-time turns, turned back. With `test_time_focus`, the turned passes see only the voxels
    /// around `first`'s proposals (a frame without any runs none).
    fn fused_over_turns(&self, batch: &Batch, first: Vec<Detections>) -> Vec<Detections> {
        let post = self.config.model.post();
        let rows: Vec<Vec<usize>> = (0..batch.len())
            .map(|s| {
                let rows = batch.rows(s);
                if post.test_time_focus <= 0.0 {
                    return rows.collect();
                }
                let d = &first[s];
                let around: Vec<Box3d> = d.boxes.iter().zip(&d.scores).filter(|(_, s)| f64::from(**s) >= post.test_time_focus_score).map(|(b, _)| *b).collect();
                focus(&batch.points(s), &around, post.test_time_focus).into_iter().map(|i| rows.start + i).collect()
            })
            .collect();
        let mut passes: Vec<Vec<Detections>> = first.into_iter().map(|d| vec![d]).collect();
        for &turn in self.turns.iter().filter(|t| !t.is_identity()) {
            let (turned, kept) = turned_batch(batch, &rows, turn);
            let found = if kept.is_empty() { Vec::new() } else { self.forward(&turned) };
            let mut found = kept.into_iter().zip(found).peekable();
            for (s, seen) in passes.iter_mut().enumerate() {
                let d = found.next_if(|(k, _)| *k == s).map(|(_, d)| d).unwrap_or_default();
                seen.push(Detections { boxes: d.boxes.iter().map(|b| turn.undo(b)).collect(), scores: d.scores });
            }
        }
        passes
            .iter()
            .map(|seen| {
                let mut d = fuse(seen, post.test_time_radius, post.merge_heading);
                if let Some(max) = post.max_boxes {
                    d.boxes.truncate(max);
                    d.scores.truncate(max);
                }
                d
            })
            .collect()
    }
}
