//! Fitting a checkpoint's facing stage (`model::facing`): the direction of each box's heading,
//! read from the points in it, learned from the run's own boxes on frames it is not scored on.
//!
//! ```text
//! runs/<name>/checkpoints/step-…/facing.json    the stage, beside the weights it was fitted for
//! ```
//!
//! It lives beside the weights because it reads the boxes those weights place: a run trained
//! further has new checkpoints and no stage until it is fitted again.

use std::path::Path;

use anyhow::{Context, Result, ensure};
use data_jrdb::{Box3d, Split};
use eval::jrdb::Detection;
use model::{FacingClassifier, FacingFeatures, FacingSample};

use crate::backend::BackendKind;
use crate::checkpoint::Slot;
use crate::data::eval_loader;
use crate::infer::load_run_on;
use crate::run_dir::{RunDir, write_atomic};
use crate::validate::{FrameResult, HeadingError, matched_by_centre, visit_split};

/// The stage's file in a checkpoint's folder.
pub const FACING_FILE: &str = "facing.json";
/// Fewer boxes than this are too few to fit from.
pub const MIN_SAMPLES: usize = 200;

/// The stage stored in checkpoint folder `dir`, if it has one.
pub fn load_facing(dir: &Path) -> Result<Option<FacingClassifier>> {
    let path = dir.join(FACING_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let stage: FacingClassifier = serde_json::from_str(&text).with_context(|| format!("{} is not a facing stage", path.display()))?;
    stage.check().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(Some(stage))
}

/// Which boxes the stage learns from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum FitBoxes {
    /// The run's own detections matched to people: the boxes it will be applied to, with their
    /// errors of place and axis.
    #[default]
    Detections,
    /// The labelled boxes of the counted people.
    Labels,
}

/// How to fit.
#[derive(Debug, Clone)]
pub struct FacingOptions {
    /// The split to fit on (frames the run is not scored on: its training split).
    pub split: Split,
    /// Also report the direction before and after the stage on this split (the validation).
    pub score_on: Option<Split>,
    /// The checkpoint (default: latest).
    pub checkpoint: Option<Slot>,
    /// Backend override.
    pub backend: Option<BackendKind>,
    /// Run on this JRDB-format tree instead of the run's own data.
    pub data_root: Option<std::path::PathBuf>,
    /// Which boxes to learn from.
    pub boxes: FitBoxes,
    /// The histogram.
    pub features: FacingFeatures,
    /// Ridge weight on the standardised features.
    pub l2: f64,
    /// Store the stage beside the checkpoint's weights.
    pub write: bool,
    /// Progress bars on stderr.
    pub verbose: bool,
}

impl Default for FacingOptions {
    fn default() -> Self {
        Self {
            split: Split::Train,
            score_on: Some(Split::Val),
            checkpoint: None,
            backend: None,
            data_root: None,
            boxes: FitBoxes::Detections,
            features: FacingFeatures::default(),
            l2: 0.01,
            write: false,
            verbose: false,
        }
    }
}

/// What fitting found.
#[derive(Debug, Clone)]
pub struct FacingReport {
    /// The stage.
    pub stage: FacingClassifier,
    /// Frames it was fitted on.
    pub frames: usize,
    /// On `score_on`: the heading of matched boxes as the network gives it, and after the stage.
    pub scored: Option<(HeadingError, HeadingError)>,
    /// Where it was written, with `write`.
    pub written: Option<std::path::PathBuf>,
}

impl std::fmt::Display for FacingReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = &self.stage;
        writeln!(
            f,
            "facing stage: {} boxes from {} frames, {} features ({:.2} m grid, {} projections, {}slice moments, {}the detector's direction), ridge {}; {:.1} % of them told right",
            s.samples,
            self.frames,
            s.features.len(),
            s.features.cell,
            s.features.profile_cell.map_or("no".to_string(), |c| format!("{c:.2} m")),
            if s.features.slice_moments { "" } else { "no " },
            if s.features.detector_direction { "" } else { "not " },
            s.l2,
            100.0 * s.training_accuracy
        )?;
        if let Some((network, staged)) = &self.scored {
            writeln!(f, "validation, the network's heading: {network}")?;
            writeln!(f, "validation, after the stage:       {staged}")?;
        }
        match &self.written {
            Some(p) => write!(f, "written to {}", p.display()),
            None => write!(f, "not written (--write stores it beside the checkpoint)"),
        }
    }
}

/// The samples of one frame: each matched detection's box (or each counted label's), with the
/// person's true heading.
fn frame_samples(frame: &FrameResult, cloud: &[[f32; 3]], opts: &FacingOptions, protocol: &eval::Protocol) -> Vec<FacingSample> {
    let boxes: Vec<(&Box3d, f64)> = match opts.boxes {
        FitBoxes::Detections => matched_by_centre(frame, protocol).into_iter().map(|(d, g)| (&d.bbox, g.rot_z)).collect(),
        FitBoxes::Labels => frame.scored_gt(protocol).into_iter().map(|g| (g, g.rot_z)).collect(),
    };
    boxes.into_iter().filter_map(|(b, truth)| FacingSample::new(&opts.features, cloud, b, truth)).collect()
}

/// Fits the stage for `run`'s checkpoint on `opts.split` with the network's own headings (any
/// stored stage is not applied while fitting), reports it on `opts.score_on` and, with
/// `opts.write`, stores it beside the checkpoint.
pub fn fit_facing(run: &RunDir, opts: &FacingOptions) -> Result<FacingReport> {
    let mut cfg = run.config()?;
    cfg.model.post_mut().facing_stage = false;
    let detector = load_run_on(run, cfg, opts.data_root.as_deref(), opts.backend, opts.checkpoint.unwrap_or(Slot::Latest))?;
    let protocol = detector.config().eval.protocol();
    let loader = eval_loader(detector.config(), opts.split)?;
    let (mut samples, mut frames) = (Vec::new(), 0);
    visit_split(|b| detector.detect_batch(b), &loader, opts.verbose, |frame, cloud| {
        frames += 1;
        samples.extend(frame_samples(&frame, cloud, opts, &protocol));
    })?;
    ensure!(
        samples.len() >= MIN_SAMPLES,
        "{frames} frames of {} gave {} boxes with points to learn from, fewer than the {MIN_SAMPLES} a facing stage needs",
        detector.config().data.root.display(),
        samples.len()
    );
    let stage = FacingClassifier::fit(opts.features, &samples, opts.l2).map_err(anyhow::Error::msg)?;
    drop(samples);
    let scored = match opts.score_on {
        None => None,
        Some(split) => {
            let loader = eval_loader(detector.config(), split)?;
            let (mut network, mut staged) = (Vec::new(), Vec::new());
            visit_split(|b| detector.detect_batch(b), &loader, opts.verbose, |frame, cloud| {
                let mut boxes: Vec<Box3d> = frame.detections.iter().map(|d| d.bbox).collect();
                stage.orient_all(cloud, &mut boxes);
                let turned: Vec<Detection> = boxes.into_iter().zip(&frame.detections).map(|(bbox, d)| Detection { bbox, score: d.score }).collect();
                staged.push(FrameResult { detections: turned, ..frame.clone() });
                network.push(frame);
            })?;
            HeadingError::of(&network, &protocol).zip(HeadingError::of(&staged, &protocol))
        }
    };
    let written = if opts.write {
        let path = detector.checkpoint().join(FACING_FILE);
        write_atomic(&path, serde_json::to_string_pretty(&stage)?.as_bytes())?;
        Some(path)
    } else {
        None
    };
    Ok(FacingReport { stage, frames, scored, written })
}
