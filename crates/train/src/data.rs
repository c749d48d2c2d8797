//! The run's data: the simulated tree generated on first use, the two splits, and their loaders.

use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use data_jrdb::sim::{SimulateConfig, SynthSummary, synth};
use data_jrdb::{DataConfig, Dataset, DatasetFormat, Loader, LoaderConfig, Split};

use crate::config::RunConfig;

/// Makes sure `data.root` exists: when it does not and the config has `[data.simulate]`, the
/// simulated tree is generated there (into a temporary sibling folder renamed into place when
/// complete, so an interrupted generation is redone rather than half-used). Returns what was
/// written.
pub fn ensure_dataset(cfg: &DataConfig) -> Result<Option<SynthSummary>> {
    if cfg.simulate.is_some() && cfg.format != DatasetFormat::Jrdb {
        bail!("data.simulate writes a JRDB-format tree, but data.format is {}: drop one of them", cfg.format);
    }
    ensure_tree(&cfg.root, cfg.simulate.as_ref(), "data")
}

/// [`ensure_dataset`], and every `data.also_train` tree beside it: what training reads.
pub fn ensure_training_data(cfg: &DataConfig) -> Result<Option<SynthSummary>> {
    for extra in &cfg.also_train {
        ensure_tree(&extra.root, extra.simulate.as_ref(), "data.also_train")?;
    }
    ensure_dataset(cfg)
}

fn ensure_tree(root: &Path, simulate: Option<&SimulateConfig>, section: &str) -> Result<Option<SynthSummary>> {
    if root.exists() {
        return Ok(None);
    }
    let Some(sim) = simulate else {
        bail!("data root {} does not exist (point {section}.root at a JRDB tree, or add a simulate section to generate a simulated one)", root.display());
    };
    let tmp = crate::run_dir::tmp_name(root);
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp)?;
    }
    if let Some(parent) = tmp.parent() {
        std::fs::create_dir_all(parent)?;
    }
    let synth_cfg = sim.synth();
    eprintln!(
        "generating the simulated dataset{} ({} sequences × {} frames, seed {}) at {}",
        sim.preset.map_or_else(String::new, |p| format!(" {}", p.name())),
        synth_cfg.sequences,
        synth_cfg.frames,
        synth_cfg.seed,
        root.display()
    );
    let summary = synth(&tmp, &synth_cfg).with_context(|| format!("simulating into {}", tmp.display()))?;
    std::fs::rename(&tmp, root).with_context(|| format!("renaming {} to {}", tmp.display(), root.display()))?;
    Ok(Some(summary))
}

/// Opens one split of the tree, keeping every `stride`-th frame.
pub fn open_split(cfg: &DataConfig, split: Split, stride: usize) -> Result<Arc<Dataset>> {
    let dcfg = cfg.dataset(split);
    let mut ds = Dataset::open(&cfg.root, &dcfg).with_context(|| format!("opening {:?} split of {}", split, cfg.root.display()))?;
    if stride > 1 {
        ds.frames = ds.frames.into_iter().step_by(stride).collect();
    }
    if ds.is_empty() {
        bail!("the {:?} split of {} has no frames (sequences: {:?})", split, cfg.root.display(), ds.sequences);
    }
    Ok(Arc::new(ds))
}

/// The training loader: shuffled by `seed`, augmented, capped.
pub fn train_loader(cfg: &RunConfig) -> Result<Loader> {
    let mut ds = Arc::into_inner(open_split(&cfg.data, cfg.data.train_split, 1)?).expect("a fresh dataset has one owner");
    for extra in &cfg.data.also_train {
        // Extra trees are JRDB-format (simulated) whatever `data.format` is.
        let dcfg = data_jrdb::DatasetConfig { format: DatasetFormat::Jrdb, ..cfg.data.dataset(cfg.data.train_split) };
        let more = Dataset::open(&extra.root, &dcfg).with_context(|| format!("opening {:?} split of {} (data.also_train)", cfg.data.train_split, extra.root.display()))?;
        if more.is_empty() {
            bail!("the {:?} split of {} (data.also_train) has no frames", cfg.data.train_split, extra.root.display());
        }
        ds.append(more).context("data.also_train")?;
    }
    Ok(Loader::new(
        Arc::new(ds),
        LoaderConfig {
            batch_size: cfg.train.batch_size,
            shuffle: true,
            drop_last: cfg.train.drop_last,
            seed: cfg.seed,
            sample: cfg.data.train_sample(),
            on_bad_frame: cfg.data.on_bad_frame,
            prefetch: cfg.data.prefetch,
        },
    ))
}

/// An evaluation loader over `split`: file order, no augmentation, no cap, every `eval.frame_stride`-th frame.
pub fn eval_loader(cfg: &RunConfig, split: Split) -> Result<Loader> {
    let ds = open_split(&cfg.data, split, cfg.eval.frame_stride)?;
    Ok(Loader::new(
        ds,
        LoaderConfig {
            batch_size: cfg.eval.batch_size,
            shuffle: false,
            drop_last: false,
            seed: cfg.seed,
            sample: cfg.data.eval_sample(),
            on_bad_frame: cfg.data.on_bad_frame,
            prefetch: cfg.data.prefetch,
        },
    ))
}
