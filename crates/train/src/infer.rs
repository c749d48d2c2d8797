//! Inference from a run's checkpoint: detections for a split written as pmunet JSON and as the
//! official KITTI-style txt tree (with the matching GT tree), scored with `eval`, optionally drawn.
//!
//! ```text
//! runs/<name>/detections/<split>/json/<sequence>.json     pmunet detection files (eval::jrdb)
//! runs/<name>/detections/<split>/kitti/<sequence>/<frame>.txt   detections, official layout
//! runs/<name>/detections/<split>/kitti_gt/<sequence>/<frame>.txt   the GT the official tool reads
//! runs/<name>/detections/<split>/eval.json, eval.txt, pr.csv, pr.png
//! runs/<name>/render/<split>/<sequence>_<frame>.png   with --render N
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Result;
use data_jrdb::{Loader, Split};
use eval::jrdb::{DetectionFile, write_detections};
use eval::kitti::FileKind;
use serde_json::json;

use crate::backend::BackendKind;
use crate::checkpoint::Slot;
use crate::detector::RunDetector;
use crate::data::{ensure_dataset, eval_loader};
use crate::render::render_frames;
use crate::run_dir::RunDir;
use crate::config::RunConfig;
use crate::validate::{FrameResult, HeadingError, RANGE_BANDS, ap3d_by_range, detect_split, format_by_range, to_eval_frames};

/// What to infer.
#[derive(Debug, Clone)]
pub struct InferOptions {
    /// The split.
    pub split: Split,
    /// `latest` (default) or `best`, the one that scored highest on the validation frames (so its
    /// AP on those frames is an optimistic estimate).
    pub checkpoint: Option<Slot>,
    /// Draw the first N frames.
    pub render: usize,
    /// Backend override.
    pub backend: Option<BackendKind>,
    /// Progress bars and the report table on stderr.
    pub verbose: bool,
    /// Run on this dataset instead of the run's own `data.root` (never simulated).
    pub data_root: Option<PathBuf>,
    /// Its layout, when not the run's `data.format` (a JRDB-trained run scored on KITTI, say).
    pub data_format: Option<data_jrdb::DatasetFormat>,
    /// Config overrides (`model.post.merge_radius=0.4`), as `--set` of training.
    pub set: Vec<String>,
    /// Write detections here instead of `<run>/detections/<split>/`.
    pub out: Option<PathBuf>,
}

/// What inference wrote and scored.
#[derive(Debug, Clone)]
pub struct InferOutput {
    /// The detections folder.
    pub dir: PathBuf,
    /// AP3D at 0.3/0.5/0.7.
    pub ap3d: [f64; 3],
    /// The report's table.
    pub table: String,
    /// Frames scored.
    pub frames: usize,
    /// AP3D at 0.3/0.5/0.7 per range band (`validate::RANGE_BANDS`).
    pub ap3d_by_range: [[f64; 3]; 3],
    /// Heading error of matched detections.
    pub heading: Option<HeadingError>,
}

/// The split's folder name.
pub fn split_name(split: Split) -> &'static str {
    match split {
        Split::Train => "train",
        Split::Val => "val",
        Split::TrainVal => "train_val",
    }
}

/// The run's model (checkpoint `slot`, settings `cfg`) on `backend` (default: the config's),
/// pointed at `data_root` (default: the run's own data, simulated on first use), with that data
/// in place.
pub fn load_run_on(run: &RunDir, mut cfg: RunConfig, data_root: Option<&Path>, backend: Option<BackendKind>, slot: Slot) -> Result<RunDetector> {
    if let Some(root) = data_root {
        anyhow::ensure!(root.exists(), "--data-root {}: no such folder", root.display());
        cfg.data.root = root.to_path_buf();
        cfg.data.simulate = None;
    }
    if let Some(b) = backend {
        cfg.backend = b;
    }
    let detector = RunDetector::with_config(&run.root, cfg, slot, None)?;
    ensure_dataset(&detector.config().data)?;
    Ok(detector)
}

/// [`load_run_on`], then every frame of `split`'s detections: the detector, the split's loader
/// and the frames.
pub fn detect_run_split(
    run: &RunDir,
    cfg: RunConfig,
    data_root: Option<&Path>,
    backend: Option<BackendKind>,
    slot: Slot,
    split: Split,
    verbose: bool,
) -> Result<(RunDetector, Loader, Vec<FrameResult>)> {
    let detector = load_run_on(run, cfg, data_root, backend, slot)?;
    let loader = eval_loader(detector.config(), split)?;
    let frames = detect_split(|b| detector.detect_batch(b), &loader, verbose)?;
    Ok((detector, loader, frames))
}

/// Loads the run's model from a checkpoint and writes, scores and draws its detections.
pub fn infer(run: &RunDir, opts: &InferOptions) -> Result<InferOutput> {
    let mut cfg = run.config_with(&opts.set)?;
    if let Some(format) = opts.data_format {
        cfg.data.format = format;
    }
    let slot = opts.checkpoint.unwrap_or(Slot::Latest);
    let (detector, loader, frames) = detect_run_split(run, cfg, opts.data_root.as_deref(), opts.backend, slot, opts.split, opts.verbose)?;
    let cfg = detector.config();
    let dir = opts.out.clone().unwrap_or_else(|| run.detections(split_name(opts.split)));
    let protocol = cfg.eval.protocol();
    let (report, by_range) = write_results(&frames, &dir, &protocol)?;
    let heading = HeadingError::of(&frames, &protocol);
    let mut eval_json = report.to_json();
    if let Some(obj) = eval_json.as_object_mut() {
        obj.insert("checkpoint".into(), json!(detector.checkpoint().file_name().map(|n| n.to_string_lossy().into_owned())));
        obj.insert("split".into(), json!(split_name(opts.split)));
        obj.insert("data_root".into(), json!(cfg.data.root));
        let bands: serde_json::Map<String, serde_json::Value> = RANGE_BANDS
            .iter()
            .zip(&by_range)
            .map(|((lo, hi), a)| (format!("{lo:.0}-{hi:.0}"), json!({"0.3": a[0], "0.5": a[1], "0.7": a[2]})))
            .collect();
        obj.insert("ap3d_by_range_non_official".into(), serde_json::Value::Object(bands));
        obj.insert("heading".into(), json!(heading));
        obj.insert("facing_stage".into(), json!(detector.facing().is_some()));
        obj.insert("overrides".into(), json!(opts.set));
    }
    std::fs::write(dir.join("eval.json"), serde_json::to_string_pretty(&eval_json)?)?;
    let stage = if detector.facing().is_some() { " (directions from the checkpoint's facing stage)" } else { "" };
    let heading_text = heading.map_or_else(|| "no matched box".to_string(), |h| format!("{h}{stage}"));
    let table = format!("{}\nAP3D by range (non-official): {}\n{heading_text}\n", report.to_table().trim_end(), format_by_range(&by_range));
    std::fs::write(dir.join("eval.txt"), &table)?;
    if opts.render > 0 {
        render_frames(loader.dataset(), &frames[..opts.render.min(frames.len())], &run.renders(split_name(opts.split)), cfg.eval.max_range)?;
    }
    Ok(InferOutput { dir, ap3d: [report.ap3d[0].ap, report.ap3d[1].ap, report.ap3d[2].ap], table, frames: frames.len(), ap3d_by_range: by_range, heading })
}

/// Writes frame results as pmunet JSON (`json/`), official detection txt (`kitti/`) and GT txt
/// (`kitti_gt/`) under `dir`, plus PR CSV and PNG, and returns the report and the AP3D by range
/// band.
pub fn write_results(frames: &[FrameResult], dir: &std::path::Path, protocol: &eval::Protocol) -> Result<(eval::Report, [[f64; 3]; 3])> {
    let mut by_seq: BTreeMap<&str, DetectionFile> = BTreeMap::new();
    for f in frames {
        let file = by_seq.entry(&f.sequence).or_insert_with(|| DetectionFile { sequence: Some(f.sequence.clone()), detections: BTreeMap::new() });
        file.detections.insert(f.name.clone(), f.detections.clone());
    }
    for (seq, file) in &by_seq {
        write_detections(&dir.join("json").join(format!("{seq}.json")), file)?;
    }
    let eval_frames = to_eval_frames(frames);
    eval::dataset::write_kitti_tree(&dir.join("kitti"), &eval_frames, FileKind::Detections)?;
    eval::dataset::write_kitti_tree(&dir.join("kitti_gt"), &eval_frames, FileKind::GroundTruth)?;
    let report = eval::Report::compute(&eval_frames, protocol);
    report.write_pr_csv(&dir.join("pr.csv"))?;
    crate::plots::register_fonts();
    eval::plot::plot_pr(&report, &dir.join("pr.png"))?;
    Ok((report, ap3d_by_range(&eval_frames, protocol)))
}
