//! `JrdbDataset`: the frames of a split, and `Frame`, one merged scan with its boxes.

use std::path::{Path, PathBuf};

use crate::box3d::Box3d;
use crate::calibration::{Calibration, Lidar};
use crate::error::{DataError, ErrorKind, Result};
use crate::labels::{Label, read_labels};
use crate::pcd::{NonFinite, read_pcd};
use crate::split::{DEFAULT_VAL_SEQUENCES, Layout, Split, select_sequences};

/// What to do with a frame whose files are malformed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnBadFrame {
    /// Stop with the error.
    #[default]
    Fail,
    /// Print a warning naming the file and go on without the frame (a long training run survives).
    Skip,
}

/// Which frames to read and how strictly.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct DatasetConfig {
    /// Split to use.
    pub split: Split,
    /// Validation sequences (default: JRDB's 7).
    pub val_sequences: Vec<String>,
    /// If set, exactly these sequences (overrides `split`); each must exist.
    pub sequences: Option<Vec<String>>,
    /// Non-finite points in PCD files.
    pub non_finite: NonFinite,
    /// Malformed frames or label files.
    pub on_bad_frame: OnBadFrame,
    /// Whether a sequence without `labels_3d/<seq>.json` is an error (else its frames have no boxes).
    pub require_labels: bool,
}

impl Default for DatasetConfig {
    fn default() -> Self {
        Self {
            split: Split::Train,
            val_sequences: DEFAULT_VAL_SEQUENCES.map(String::from).to_vec(),
            sequences: None,
            non_finite: NonFinite::Drop,
            on_bad_frame: OnBadFrame::Fail,
            require_labels: true,
        }
    }
}

/// Where a frame's files are and its labels (read once when the dataset opens).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRef {
    /// Sequence name.
    pub sequence: String,
    /// Frame name without extension (`000123`).
    pub name: String,
    /// Upper cloud file.
    pub upper: PathBuf,
    /// Lower cloud file.
    pub lower: PathBuf,
    /// Its pedestrian labels (empty when the frame has none).
    pub labels: Vec<Label>,
}

/// One merged scan in the base frame with its pedestrian boxes.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Sequence name.
    pub sequence: String,
    /// Frame name without extension (`000123`).
    pub name: String,
    /// Finite points in the base frame, the upper cloud first (`[upper, lower]`).
    pub points: Vec<[f32; 3]>,
    /// How many of `points` came from the upper LiDAR.
    pub n_upper: usize,
    /// Non-finite points dropped from both files.
    pub dropped_non_finite: usize,
    /// Pedestrian boxes.
    pub boxes: Vec<Box3d>,
    /// `attributes.num_points` of each box.
    pub num_points: Vec<i64>,
    /// `label_id` of each box.
    pub label_ids: Vec<String>,
}

/// The frames of one split of a JRDB-format tree.
#[derive(Debug, Clone)]
pub struct JrdbDataset {
    /// The resolved layout.
    pub layout: Layout,
    /// LiDAR → base transforms.
    pub calibration: Calibration,
    /// Frames in sequence order, then file-name order.
    pub frames: Vec<FrameRef>,
    /// The sequences used, sorted.
    pub sequences: Vec<String>,
    /// Non-finite point policy for reads.
    pub non_finite: NonFinite,
}

fn warn(e: &DataError) {
    eprintln!("warning: skipping: {e}");
}

impl JrdbDataset {
    /// Appends another tree's frames (trained on together); both must share one calibration,
    /// which merges every frame's two clouds.
    pub fn append(&mut self, other: JrdbDataset) -> Result<()> {
        if other.calibration != self.calibration {
            return Err(DataError::new(other.layout.calibration_file(), ErrorKind::Mismatch(format!("calibration differs from {}'s; trees trained on together must share one", self.layout.root.display()))));
        }
        self.frames.extend(other.frames);
        self.sequences.extend(other.sequences);
        Ok(())
    }

    /// Opens a tree (a plain root or one holding `train_dataset_with_activity/`) and lists its frames.
    pub fn open(dir: &Path, cfg: &DatasetConfig) -> Result<Self> {
        let layout = Layout::resolve(dir)?;
        let calibration = Calibration::read(&layout.calibration_file())?;
        let present = layout.sequences()?;
        let sequences = match &cfg.sequences {
            Some(list) => list.clone(),
            None => select_sequences(&present, cfg.split, &cfg.val_sequences),
        };
        let mut frames = Vec::new();
        for seq in &sequences {
            match list_sequence(&layout, seq, cfg) {
                Ok(mut f) => frames.append(&mut f),
                Err(e) if cfg.on_bad_frame == OnBadFrame::Skip => warn(&e),
                Err(e) => return Err(e),
            }
        }
        Ok(Self { layout, calibration, frames, sequences, non_finite: cfg.non_finite })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether there are no frames.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Reads frame `i`: both clouds into the base frame, merged as `[upper, lower]`.
    pub fn load(&self, i: usize) -> Result<Frame> {
        let r = &self.frames[i];
        let up = read_pcd(&r.upper, self.non_finite)?;
        let lo = read_pcd(&r.lower, self.non_finite)?;
        let (tu, tl) = (self.calibration.lidar(Lidar::Upper), self.calibration.lidar(Lidar::Lower));
        let mut points = Vec::with_capacity(up.xyz.len() + lo.xyz.len());
        points.extend(up.xyz.iter().map(|&p| tu.to_base(p)));
        points.extend(lo.xyz.iter().map(|&p| tl.to_base(p)));
        Ok(Frame {
            sequence: r.sequence.clone(),
            name: r.name.clone(),
            n_upper: up.xyz.len(),
            points,
            dropped_non_finite: up.dropped_non_finite + lo.dropped_non_finite,
            boxes: r.labels.iter().map(|l| l.bbox).collect(),
            num_points: r.labels.iter().map(|l| l.num_points).collect(),
            label_ids: r.labels.iter().map(|l| l.id.clone()).collect(),
        })
    }
}

fn list_sequence(layout: &Layout, seq: &str, cfg: &DatasetConfig) -> Result<Vec<FrameRef>> {
    let up_dir = layout.cloud_dir(Lidar::Upper, seq);
    let lo_dir = layout.cloud_dir(Lidar::Lower, seq);
    for d in [&up_dir, &lo_dir] {
        if !d.is_dir() {
            return Err(DataError::new(d, ErrorKind::Layout(format!("sequence folder of `{seq}` is missing"))));
        }
    }
    let labels_path = layout.labels_file(seq);
    let mut labels = if labels_path.is_file() {
        read_labels(&labels_path)?
    } else if cfg.require_labels {
        return Err(DataError::new(&labels_path, ErrorKind::Layout(format!("labels of sequence `{seq}` are missing"))));
    } else {
        Default::default()
    };
    let mut names = Vec::new();
    let rd = std::fs::read_dir(&up_dir).map_err(|e| DataError::io(&up_dir, e))?;
    for e in rd {
        let e = e.map_err(|e| DataError::io(&up_dir, e))?;
        let f = e.file_name().to_string_lossy().into_owned();
        if let Some(stem) = f.strip_suffix(".pcd") {
            names.push(stem.to_string());
        }
    }
    names.sort();
    let mut out = Vec::with_capacity(names.len());
    for name in names {
        let upper = up_dir.join(format!("{name}.pcd"));
        let lower = lo_dir.join(format!("{name}.pcd"));
        if !lower.is_file() {
            let e = DataError::new(&upper, ErrorKind::Layout(format!("upper cloud has no lower twin {}", lower.display())));
            if cfg.on_bad_frame == OnBadFrame::Skip {
                warn(&e);
                continue;
            }
            return Err(e);
        }
        let labels = labels.remove(&format!("{name}.pcd")).unwrap_or_default();
        out.push(FrameRef { sequence: seq.to_string(), name, upper, lower, labels });
    }
    Ok(out)
}
