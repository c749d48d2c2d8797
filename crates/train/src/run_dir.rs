//! The run folder (DESIGN.md, "Runs on disk"):
//!
//! ```text
//! runs/<name>/
//!   config.toml        the fully resolved config (defaults included)
//!   metrics.csv        one row per training step
//!   epochs.csv         one row per epoch, with validation AP
//!   summary.json       written when training finishes (what sweeps read)
//!   checkpoints/       step-<n>/ folders + `latest` and `best` pointer files
//!   plots/*.png        curves, redrawn every epoch
//!   detections/<split>/{json/, kitti/}, eval.json   from `infer`
//!   render/<split>/*.png                            from `infer --render`
//! ```
//!
//! Nothing a run wrote is overwritten except by an explicit flag (`--resume` continues, `--overwrite`
//! starts over).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use crate::checkpoint::Slot;
use crate::config::RunConfig;

/// Paths of one run folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunDir {
    /// The folder.
    pub root: PathBuf,
}

/// How to treat an existing run folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Existing {
    /// It must not hold a run yet.
    Refuse,
    /// Continue the run in it.
    Resume,
    /// Delete it and start over.
    Overwrite,
}

impl RunDir {
    /// The folder at `root` (nothing is created).
    pub fn at(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// Creates (or reopens, per `existing`) the run folder and writes the resolved config.
    /// On resume the stored config must equal `cfg` (the run continues with the settings it began with).
    pub fn create(root: impl Into<PathBuf>, cfg: &RunConfig, existing: Existing) -> Result<Self> {
        let dir = Self::at(root);
        let has_run = dir.config_file().exists();
        // A run that failed before its first step (bad data, a missing `train.init`) left only
        // its config: nothing to lose, so the next attempt starts over without --overwrite.
        let existing = if existing == Existing::Refuse && has_run && !dir.started() { Existing::Overwrite } else { existing };
        match (existing, has_run) {
            (Existing::Refuse, true) => bail!(
                "{} already holds a run; pass --resume to continue it or --overwrite to start over",
                dir.root.display()
            ),
            (Existing::Resume, false) => bail!("--resume: {} holds no run to continue", dir.root.display()),
            (Existing::Resume, true) => {
                let stored = dir.config()?;
                if stored != *cfg {
                    bail!(
                        "--resume: the config differs from the one {} was started with (in {}); resume with that one",
                        dir.root.display(),
                        dir.config_file().display()
                    );
                }
            }
            (Existing::Overwrite, true) => {
                std::fs::remove_dir_all(&dir.root).with_context(|| format!("removing {}", dir.root.display()))?;
            }
            _ => {}
        }
        for d in [dir.root.clone(), dir.checkpoints(), dir.plots()] {
            std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
        }
        if !has_run || existing == Existing::Overwrite {
            write_atomic(&dir.config_file(), cfg.to_toml()?.as_bytes())?;
        }
        Ok(dir)
    }

    /// Whether the run has taken a step: a metrics row, a checkpoint or a summary.
    fn started(&self) -> bool {
        self.metrics_csv().exists() || self.checkpoints().join(Slot::Latest.file()).exists() || self.summary_json().exists()
    }

    /// The stored, resolved config.
    pub fn config(&self) -> Result<RunConfig> {
        let text = std::fs::read_to_string(self.config_file())
            .with_context(|| format!("{} holds no run (no config.toml)", self.root.display()))?;
        RunConfig::from_toml_str(&text).with_context(|| format!("in {}", self.config_file().display()))
    }

    /// The stored config with `overrides` (`key.path=value`, as `--set`) applied for one use;
    /// the file is unchanged.
    pub fn config_with(&self, overrides: &[String]) -> Result<RunConfig> {
        if overrides.is_empty() {
            return self.config();
        }
        RunConfig::load(&self.config_file(), overrides)
    }

    /// `config.toml`.
    pub fn config_file(&self) -> PathBuf {
        self.root.join("config.toml")
    }
    /// `metrics.csv`.
    pub fn metrics_csv(&self) -> PathBuf {
        self.root.join("metrics.csv")
    }
    /// `epochs.csv`.
    pub fn epochs_csv(&self) -> PathBuf {
        self.root.join("epochs.csv")
    }
    /// `summary.json`.
    pub fn summary_json(&self) -> PathBuf {
        self.root.join("summary.json")
    }
    /// `checkpoints/`.
    pub fn checkpoints(&self) -> PathBuf {
        self.root.join("checkpoints")
    }
    /// `plots/`.
    pub fn plots(&self) -> PathBuf {
        self.root.join("plots")
    }
    /// `detections/<split>/`.
    pub fn detections(&self, split: &str) -> PathBuf {
        self.root.join("detections").join(split)
    }
    /// `render/<split>/`.
    pub fn renders(&self, split: &str) -> PathBuf {
        self.root.join("render").join(split)
    }
}

/// Writes a file atomically: a temporary file in the same folder, then a rename over the target.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = tmp_name(path);
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))
}

/// `dir/.name.tmp` for `dir/name`.
pub fn tmp_name(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp"))
}
