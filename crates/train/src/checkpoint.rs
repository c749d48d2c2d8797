//! Checkpoints: model, optimizer and loop state, written so that a crash never leaves a half-written
//! checkpoint behind.
//!
//! Layout under `checkpoints/`: one folder per saved step, `step-000123/{model.bpk, optim.bpk,
//! state.json}`, and two pointer files, `latest` and `best`, each holding a folder name. A folder is
//! written completely under a temporary name and renamed; then the pointer is replaced atomically
//! (temporary file + rename). Folders no pointer names are removed afterwards. So at every instant
//! `latest` and `best` name complete checkpoints.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use burn::module::Module;
use burn::optim::ModuleOptimizer;
use serde::{Deserialize, Serialize};

use crate::run_dir::{tmp_name, write_atomic};

/// Where the training loop stands: everything besides the weights and Adam's moments that a resumed
/// run needs to continue exactly (the data order and augmentation are functions of (seed, epoch,
/// frame), so the position in the epoch is the whole RNG state).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct TrainState {
    /// Steps done (optimizer updates).
    pub step: u64,
    /// The epoch in progress (0-based); equals the number of finished epochs at an epoch boundary.
    pub epoch: usize,
    /// Batches of `epoch` already done.
    pub batch: usize,
    /// Seed of the run (checked on resume).
    pub seed: u64,
    /// Cumulative training time, seconds (validation excluded).
    pub time: f64,
    /// Sums of the loss and each term over the batches done in `epoch` (for the epoch's means).
    pub epoch_sums: Vec<(String, f64)>,
    /// Training seconds spent in `epoch` so far.
    pub epoch_seconds: f64,
    /// Best validation AP3D@0.3 so far and the epoch (1-based) it came from.
    pub best: Option<(f64, usize)>,
    /// Latest validation AP3D at 0.3/0.5/0.7 and its epoch (1-based).
    pub last_val: Option<([f64; 3], usize)>,
}

/// Which pointer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// The most recent checkpoint.
    Latest,
    /// The checkpoint with the best validation AP3D@0.3.
    Best,
}

/// `latest` or `best`, as `--checkpoint` spells it.
impl std::fmt::Display for Slot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.file())
    }
}

impl Slot {
    pub(crate) fn file(self) -> &'static str {
        match self {
            Slot::Latest => "latest",
            Slot::Best => "best",
        }
    }
}

/// Loads the weights in `path` (burnpack) into `model` (same architecture).
pub fn load_model_file<M: Module>(model: M, path: &Path) -> Result<M> {
    model.try_load_file(path).map_err(|e| anyhow::anyhow!("loading {}: {e:?}", path.display()))
}

/// A run's `checkpoints/` folder.
#[derive(Debug, Clone)]
pub struct Checkpoints {
    dir: PathBuf,
}

/// The files of one checkpoint.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckpointFiles {
    /// Its folder.
    pub dir: PathBuf,
}

impl CheckpointFiles {
    /// Model weights (burnpack).
    pub fn model(&self) -> PathBuf {
        self.dir.join("model.bpk")
    }
    /// Optimizer state (burnpack).
    pub fn optim(&self) -> PathBuf {
        self.dir.join("optim.bpk")
    }
    /// [`TrainState`] as JSON.
    pub fn state(&self) -> PathBuf {
        self.dir.join("state.json")
    }

    /// Reads the loop state.
    pub fn read_state(&self) -> Result<TrainState> {
        let text = std::fs::read_to_string(self.state()).with_context(|| format!("reading {}", self.state().display()))?;
        Ok(serde_json::from_str(&text).with_context(|| format!("parsing {}", self.state().display()))?)
    }

    /// Loads the weights into `model` (same architecture).
    pub fn load_model<M: Module>(&self, model: M) -> Result<M> {
        load_model_file(model, &self.model())
    }

    /// Loads the optimizer state into `optim`.
    pub fn load_optim(&self, optim: ModuleOptimizer) -> Result<ModuleOptimizer> {
        optim.load(self.optim()).map_err(|e| anyhow::anyhow!("loading {}: {e:?}", self.optim().display()))
    }
}

impl Checkpoints {
    /// The checkpoints of a run (`dir` is created on the first save).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The checkpoint a pointer names, if any.
    pub fn get(&self, slot: Slot) -> Result<Option<CheckpointFiles>> {
        let p = self.dir.join(slot.file());
        if !p.exists() {
            return Ok(None);
        }
        let name = std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
        let dir = self.dir.join(name.trim());
        if !dir.is_dir() {
            bail!("{} names {}, which does not exist", p.display(), dir.display());
        }
        Ok(Some(CheckpointFiles { dir }))
    }

    /// Writes a checkpoint of `model`, `optim` and `state`, then points `slots` at it and removes
    /// the folders no pointer names any more.
    pub fn save<M: Module>(&self, model: &M, optim: &ModuleOptimizer, state: &TrainState, slots: &[Slot]) -> Result<CheckpointFiles> {
        self.write(model, Some(optim), state, slots)
    }

    /// As [`save`](Self::save) without an optimizer state: weights made rather than trained (a
    /// soup), which `train.init` and inference read and `--resume` refuses.
    pub fn save_weights<M: Module>(&self, model: &M, state: &TrainState, slots: &[Slot]) -> Result<CheckpointFiles> {
        self.write(model, None, state, slots)
    }

    fn write<M: Module>(&self, model: &M, optim: Option<&ModuleOptimizer>, state: &TrainState, slots: &[Slot]) -> Result<CheckpointFiles> {
        std::fs::create_dir_all(&self.dir).with_context(|| format!("creating {}", self.dir.display()))?;
        let name = format!("step-{:09}", state.step);
        let final_dir = self.dir.join(&name);
        if !final_dir.is_dir() {
            let tmp = CheckpointFiles { dir: tmp_name(&final_dir) };
            if tmp.dir.exists() {
                std::fs::remove_dir_all(&tmp.dir)?;
            }
            std::fs::create_dir_all(&tmp.dir)?;
            model.clone().save_file(tmp.model()).map_err(|e| anyhow::anyhow!("writing {}: {e:?}", tmp.model().display()))?;
            if let Some(optim) = optim {
                optim.save(tmp.optim()).map_err(|e| anyhow::anyhow!("writing {}: {e:?}", tmp.optim().display()))?;
            }
            std::fs::write(tmp.state(), serde_json::to_string_pretty(state)?)?;
            std::fs::rename(&tmp.dir, &final_dir).with_context(|| format!("renaming {} to {}", tmp.dir.display(), final_dir.display()))?;
        }
        for s in slots {
            write_atomic(&self.dir.join(s.file()), name.as_bytes())?;
        }
        self.prune()?;
        Ok(CheckpointFiles { dir: final_dir })
    }

    /// Removes checkpoint folders (and leftover temporary ones) that no pointer names.
    fn prune(&self) -> Result<()> {
        let keep: Vec<PathBuf> = [Slot::Latest, Slot::Best].iter().filter_map(|&s| self.get(s).ok().flatten()).map(|c| c.dir).collect();
        for entry in std::fs::read_dir(&self.dir)? {
            let path = entry?.path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let is_ckpt = name.starts_with("step-") || (name.starts_with(".step-") && name.ends_with(".tmp"));
            if path.is_dir() && is_ckpt && !keep.contains(&path) {
                std::fs::remove_dir_all(&path)?;
            }
        }
        Ok(())
    }
}
