//! The run configuration: one TOML file with every setting of a run, parsed strictly.
//!
//! Every struct here denies unknown keys, so a typo is an error that names the key instead of a
//! silently ignored setting. Every key has a default (the authors' training settings) except
//! `model.kind`; the fully resolved config, defaults included, is written into the run folder.
//!
//! ```toml
//! name = "quickstart"          # run folder name (default: the config file's stem)
//! seed = 0                     # model init, data order, augmentation
//! backend = "flex"             # flex | ndarray | wgpu (overridden by --backend)
//! threads = 2                  # CPU threads (default: all cores)
//! out_dir = "runs"             # parent of the run folder (overridden by --out)
//!
//! [data]                       # root, splits, voxels, cap, augmentation
//! [data.simulate]              # present: generate a simulated tree at `root` if it is missing
//! [model]                      # kind = "person_minkunet" | "centerpoint" and its own keys
//! [train]                      # epochs, batch size, Adam, schedule, validation cadence
//! [train.schedule]             # kind = "exp_decay" (the authors') | "constant" | "cosine"
//! [eval]                       # protocol (range, min points), val batching (NMS: [model.post])
//! [kernels]                    # the op's kernel knobs: cpu = "auto" | "generic", gpu_tiled_min_cubes
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use data_jrdb::DataConfig;
use model::ModelConfig;
use serde::{Deserialize, Serialize};

use crate::backend::BackendKind;
use crate::schedule::Schedule;

/// A whole run: data, model, training and evaluation settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfig {
    /// Name of the run folder; `None`: the config file's stem.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Seed of the model's initialisation, the data order and the augmentation.
    #[serde(default)]
    pub seed: u64,
    /// Tensor backend.
    #[serde(default)]
    pub backend: BackendKind,
    /// CPU threads for the numerics; `None`: one per core.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
    /// Folder that holds run folders.
    #[serde(default = "default_out_dir")]
    pub out_dir: PathBuf,
    /// Dataset, splits, voxelization, augmentation.
    #[serde(default)]
    pub data: DataConfig,
    /// The detector (`kind` picks the model; its other keys are the model's own).
    pub model: ModelConfig,
    /// Optimisation.
    #[serde(default)]
    pub train: TrainConfig,
    /// Validation and evaluation.
    #[serde(default)]
    pub eval: EvalConfig,
    /// The sparse convolution's kernel knobs (`cpu = "auto" | "generic"`,
    /// `gpu_tiled_min_cubes`); the defaults are the fast ones.
    #[serde(default)]
    pub kernels: sparse_conv::KernelOptions,
}

fn default_out_dir() -> PathBuf {
    PathBuf::from("runs")
}

/// Optimisation, as the authors': Adam with AMSGrad, the lr set every iteration from the
/// fractional epoch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Epochs.
    pub epochs: usize,
    /// Frames per batch.
    pub batch_size: usize,
    /// Drop the last, smaller batch of an epoch.
    pub drop_last: bool,
    /// Adam.
    pub optimizer: OptimizerConfig,
    /// Learning-rate schedule.
    pub schedule: Schedule,
    /// Validate every this many epochs (and after the last); 0: only after the last.
    pub val_every: usize,
    /// Also write the latest checkpoint every this many steps (0: at epoch ends only).
    pub checkpoint_every: u64,
    /// The backend's devices to train on, data-parallel (`[0, 1, 2, 3]`: four GPUs of a CUDA
    /// machine): each step's batch is cut into one part per device and their gradients are
    /// averaged on the first. Empty: the backend's one device.
    pub devices: Vec<usize>,
    /// Start from the weights of another run's latest checkpoint (a run folder, or a shipped one
    /// such as `weights/person_minkunet`) instead of a random initialisation: fine-tuning. Adam
    /// and the schedule start afresh; `--resume` of this run still continues from its own latest.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub init: Option<PathBuf>,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 40,
            batch_size: 36,
            drop_last: false,
            optimizer: OptimizerConfig::default(),
            schedule: Schedule::default(),
            val_every: 1,
            checkpoint_every: 0,
            devices: Vec::new(),
            init: None,
        }
    }
}

/// Adam's settings; the defaults are PyTorch's (the authors'), with AMSGrad on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OptimizerConfig {
    /// β₁.
    pub beta_1: f32,
    /// β₂.
    pub beta_2: f32,
    /// ε (PyTorch's 1e-8; Burn's own default would be 1e-5).
    pub epsilon: f32,
    /// AMSGrad.
    pub amsgrad: bool,
    /// L2 weight decay (0: none).
    pub weight_decay: f32,
    /// Clip the gradient to this global L2 norm (`None`: no clipping, as the authors).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grad_clip_norm: Option<f32>,
}

impl Default for OptimizerConfig {
    fn default() -> Self {
        Self { beta_1: 0.9, beta_2: 0.999, epsilon: 1e-8, amsgrad: true, weight_decay: 0.0, grad_clip_norm: None }
    }
}

/// Validation: the JRDB protocol and how the split is batched. The score threshold and NMS that
/// make detections are the model's (`[model.post]`), so `infer` and validation share them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// Ignore GT and detections beyond this BEV range (official: 25 m); `None`: no filter (non-official).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_range: Option<f64>,
    /// Ignore GT with fewer points (official: 10).
    pub min_points: i32,
    /// Frames per validation batch (the authors evaluate one at a time).
    pub batch_size: usize,
    /// Validate on every n-th frame of the split (1: all).
    pub frame_stride: usize,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self { max_range: Some(25.0), min_points: 10, batch_size: 1, frame_stride: 1 }
    }
}

impl EvalConfig {
    /// The evaluator's protocol.
    pub fn protocol(&self) -> eval::Protocol {
        eval::Protocol { max_range: self.max_range, min_points: self.min_points, ..eval::Protocol::official() }
    }
}

impl RunConfig {
    /// Parses a config from TOML text; unknown keys are errors naming the key.
    pub fn from_toml_str(text: &str) -> Result<Self> {
        let cfg: RunConfig = toml::from_str(text).map_err(|e| anyhow::anyhow!("{e}"))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Parses a config from a TOML value (after overrides); unknown keys are errors naming the key.
    pub fn from_toml_value(value: toml::Value) -> Result<Self> {
        let cfg: RunConfig = value.try_into().map_err(|e: toml::de::Error| anyhow::anyhow!("{e}"))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Reads a config file, applying `overrides` (`key.path=value`, value in TOML syntax) first.
    /// The run's name defaults to the file's stem.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading config {}", path.display()))?;
        let mut value: toml::Value = toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        for o in overrides {
            let (key, v) = o.split_once('=').with_context(|| format!("override `{o}` is not KEY=VALUE"))?;
            set_key(&mut value, key.trim(), parse_value(v.trim())?)?;
        }
        let mut cfg = Self::from_toml_value(value).with_context(|| format!("in config {}", path.display()))?;
        if cfg.name.is_none() {
            cfg.name = path.file_stem().map(|s| s.to_string_lossy().into_owned());
        }
        Ok(cfg)
    }

    /// The fully resolved config as TOML (defaults included).
    pub fn to_toml(&self) -> Result<String> {
        Ok(toml::to_string_pretty(self)?)
    }

    /// Checks values serde cannot.
    pub fn validate(&self) -> Result<()> {
        if self.train.batch_size == 0 || self.eval.batch_size == 0 {
            bail!("train.batch_size and eval.batch_size must be at least 1");
        }
        if self.eval.frame_stride == 0 {
            bail!("eval.frame_stride must be at least 1");
        }
        if self.threads == Some(0) {
            bail!("threads must be at least 1 (leave it out for one per core)");
        }
        if self.data.voxel_size.iter().any(|&v| !(v > 0.0)) {
            bail!("data.voxel_size must be positive, got {:?}", self.data.voxel_size);
        }
        self.data.volume.validate(self.data.voxel_size).map_err(anyhow::Error::msg)?;
        self.data.augment.validate().map_err(anyhow::Error::msg)?;
        self.train.schedule.validate()?;
        self.model.validate().map_err(anyhow::Error::msg)?;
        // A quarter turn maps the lattice onto itself only when x and y cells are the same size.
        if let ModelConfig::PersonMinkunet(m) = &self.model
            && m.symmetry == model::person_minkunet::Symmetry::QuarterTurns
            && self.data.voxel_size[0] != self.data.voxel_size[1]
        {
            bail!("model.symmetry = \"quarter_turns\" needs square voxels in x and y, got data.voxel_size = {:?}", self.data.voxel_size);
        }
        Ok(())
    }
}

/// Parses an override's value as TOML (`3`, `0.5`, `true`, `"text"`, `[1, 2]`); a bare word is a string.
pub fn parse_value(text: &str) -> Result<toml::Value> {
    let doc: Result<toml::Table, _> = toml::from_str(&format!("v = {text}"));
    Ok(match doc {
        Ok(mut t) => t.remove("v").expect("parsed key"),
        Err(_) => toml::Value::String(text.to_string()),
    })
}

/// Sets `key.path` in a TOML document, creating tables on the way; a number indexes an array
/// (`data.also_train.1.root`: the second `[[data.also_train]]`). Whether the key exists in the
/// config is checked when the document is parsed into a [`RunConfig`].
pub fn set_key(doc: &mut toml::Value, key: &str, value: toml::Value) -> Result<()> {
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        bail!("bad key `{key}`");
    }
    let mut node = doc;
    for p in &parts[..parts.len() - 1] {
        node = match node {
            toml::Value::Array(items) => array_entry(items, p, key)?,
            toml::Value::Table(table) => table.entry(p.to_string()).or_insert_with(|| toml::Value::Table(Default::default())),
            _ => bail!("`{key}`: `{p}` is inside a value, not a table"),
        };
    }
    let last = parts[parts.len() - 1];
    match node {
        toml::Value::Array(items) => *array_entry(items, last, key)? = value,
        toml::Value::Table(table) => {
            table.insert(last.to_string(), value);
        }
        _ => bail!("`{key}`: the parent is not a table"),
    }
    Ok(())
}

/// The entry of `items` that the path part `p` of `key` indexes.
fn array_entry<'a>(items: &'a mut [toml::Value], p: &str, key: &str) -> Result<&'a mut toml::Value> {
    let n = items.len();
    let i: usize = p.parse().with_context(|| format!("`{key}`: `{p}` is inside an array, so it must be an index"))?;
    items.get_mut(i).with_context(|| format!("`{key}`: index {i}, but the array has {n} entries"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: &str = "[model]\nkind = \"person_minkunet\"\n";

    #[test]
    fn minimal_config_gets_the_papers_defaults() {
        let c = RunConfig::from_toml_str(MIN).unwrap();
        assert_eq!(c.train.epochs, 40);
        assert_eq!(c.train.batch_size, 36);
        assert_eq!(c.data.voxel_size, [0.05, 0.05, 0.1]);
        assert_eq!(c.data.max_voxels, Some(30_000));
        assert!(c.train.optimizer.amsgrad);
        assert_eq!(c.train.schedule, Schedule::ExpDecay { lr0: 1e-3, epoch0: 15.0, lr1: 1e-6, epoch1: 40.0 });
        assert_eq!(c.backend, BackendKind::Flex);
    }

    #[test]
    fn quarter_turns_refuse_voxels_that_are_not_square() {
        let text = "[data]\nvoxel_size = [0.2, 0.1, 0.2]\n[model]\nkind = \"person_minkunet\"\nsymmetry = \"quarter_turns\"\n";
        let e = RunConfig::from_toml_str(text).and_then(|c| c.validate()).expect_err("non-square voxels accepted").to_string();
        assert!(e.contains("square voxels") && e.contains("voxel_size"), "{e}");
        let square = text.replace("0.1", "0.2");
        RunConfig::from_toml_str(&square).and_then(|c| c.validate()).expect("square voxels refused");
    }

    #[test]
    fn augmentation_ranges_are_checked_naming_the_key() {
        for (section, key) in [
            ("scale = [1.05, 0.95]", "scale"),
            ("scale = [0.0, 1.0]", "scale"),
            ("translate = [0.5, -0.1, 0.0]", "translate"),
            ("translate = [0.5, inf, 0.0]", "translate"),
            ("jitter = -0.01", "jitter"),
            ("jitter = nan", "jitter"),
            ("drop = 1.0", "drop"),
            ("drop = -0.2", "drop"),
        ] {
            let text = format!("{MIN}[data.augment]\n{section}\n");
            let e = RunConfig::from_toml_str(&text).and_then(|c| c.validate()).expect_err(&text).to_string();
            assert!(e.contains(&format!("data.augment.{key}")), "error for `{section}` does not name the key: {e}");
        }
        let c = RunConfig::from_toml_str(&format!("{MIN}[data.augment]\ntranslate = [0.5, 0.5, 0.1]\njitter = 0.02\ndrop = 0.2\n")).unwrap();
        c.validate().unwrap();
        let a = c.data.train_sample().augment.unwrap();
        assert_eq!((a.translate, a.jitter, a.drop), ([0.5, 0.5, 0.1], 0.02, 0.2));
    }

    #[test]
    fn unknown_keys_are_errors_naming_the_key() {
        for (text, key) in [
            (format!("seeed = 1\n{MIN}"), "seeed"),
            (format!("{MIN}[train]\nepochz = 3\n"), "epochz"),
            (format!("{MIN}[train.optimizer]\namsgrd = true\n"), "amsgrd"),
            (format!("{MIN}[train.schedule]\nkind = \"constant\"\nlr = 1e-3\nlr0 = 2\n"), "lr0"),
            (format!("{MIN}[data.augment]\nflip = true\n"), "flip"),
            (format!("{MIN}[data.simulate]\nscenes = 3\n"), "scenes"),
            (format!("{MIN}[eval]\nnms = 0.3\n"), "nms"),
            ("[model]\nkind = \"person_minkunet\"\nwidht = 0.5\n".to_string(), "widht"),
        ] {
            let e = RunConfig::from_toml_str(&text).expect_err(&text).to_string();
            assert!(e.contains(key), "error for `{key}` does not name it: {e}");
        }
    }

    #[test]
    fn missing_model_kind_and_bad_values_are_errors() {
        assert!(RunConfig::from_toml_str("seed = 1\n").unwrap_err().to_string().contains("model"));
        assert!(RunConfig::from_toml_str(&format!("{MIN}[train]\nbatch_size = 0\n")).is_err());
        assert!(RunConfig::from_toml_str(&format!("backend = \"tpu\"\n{MIN}")).unwrap_err().to_string().contains("tpu"));
        assert!(RunConfig::from_toml_str(&format!("{MIN}[train.schedule]\nkind = \"exp_decay\"\nlr0 = -1.0\n")).is_err());
    }

    #[test]
    fn resolved_config_round_trips() {
        let text = format!("seed = 7\nthreads = 2\n{MIN}[data.simulate]\nsequences = 3\n[train.schedule]\nkind = \"cosine\"\nlr = 0.01\n");
        let c = RunConfig::from_toml_str(&text).unwrap();
        let back = RunConfig::from_toml_str(&c.to_toml().unwrap()).unwrap();
        assert_eq!(c, back);
        assert!(c.to_toml().unwrap().contains("epochs = 40"), "defaults are written out");
    }

    #[test]
    fn a_preset_fills_what_the_section_leaves_out() {
        let c = RunConfig::from_toml_str(&format!("{MIN}[data.simulate]\npreset = \"bench-v1\"\nseed = 7\nframes = 2\n")).unwrap();
        let s = c.data.simulate.as_ref().unwrap().synth();
        let bench = data_jrdb::sim::Preset::BenchV1.synth(7);
        assert_eq!(s, data_jrdb::sim::SynthConfig { frames: 2, ..bench });
        let plain = RunConfig::from_toml_str(&format!("{MIN}[data.simulate]\nsequences = 3\n")).unwrap();
        let s = plain.data.simulate.unwrap().synth();
        let simulator = data_jrdb::sim::SynthConfig::default();
        assert_eq!((s.sequences, s.frames, s.max_people), (3, simulator.frames, simulator.max_people), "the simulator's defaults");
        assert!(RunConfig::from_toml_str(&format!("{MIN}[data.simulate]\npreset = \"bench-v9\"\n")).is_err());
    }

    #[test]
    fn overrides_set_nested_keys_and_unknown_ones_fail() {
        let mut v: toml::Value = toml::from_str(MIN).unwrap();
        set_key(&mut v, "train.epochs", parse_value("3").unwrap()).unwrap();
        set_key(&mut v, "data.root", parse_value("some/dir").unwrap()).unwrap();
        set_key(&mut v, "train.schedule.kind", parse_value("\"constant\"").unwrap()).unwrap();
        let c = RunConfig::from_toml_value(v.clone()).unwrap();
        assert_eq!(c.train.epochs, 3);
        assert_eq!(c.data.root, PathBuf::from("some/dir"));
        assert_eq!(c.train.schedule, Schedule::Constant { lr: 1e-3 });
        set_key(&mut v, "train.nope", parse_value("1").unwrap()).unwrap();
        assert!(RunConfig::from_toml_value(v).unwrap_err().to_string().contains("nope"));
    }

    #[test]
    fn overrides_index_arrays_of_tables() {
        let text = format!("{MIN}[[data.also_train]]\nroot = \"a\"\n[[data.also_train]]\nroot = \"b\"\n[data.also_train.simulate]\nsequences = 530\n");
        let mut v: toml::Value = toml::from_str(&text).unwrap();
        set_key(&mut v, "data.also_train.1.root", parse_value("c").unwrap()).unwrap();
        set_key(&mut v, "data.also_train.1.simulate.sequences", parse_value("7").unwrap()).unwrap();
        let c = RunConfig::from_toml_value(v.clone()).unwrap();
        let roots: Vec<_> = c.data.also_train.iter().map(|t| t.root.clone()).collect();
        assert_eq!(roots, [PathBuf::from("a"), PathBuf::from("c")]);
        assert_eq!(c.data.also_train[1].simulate.as_ref().unwrap().sequences, Some(7));
        let err = set_key(&mut v, "data.also_train.2.root", parse_value("d").unwrap()).unwrap_err().to_string();
        assert!(err.contains("index 2, but the array has 2 entries"), "{err}");
        let err = set_key(&mut v, "data.also_train.first.root", parse_value("d").unwrap()).unwrap_err().to_string();
        assert!(err.contains("must be an index"), "{err}");
    }
}
