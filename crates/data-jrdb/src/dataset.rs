//! `Dataset`: the frames of a split of a dataset in any of the layouts read (JRDB, KITTI object,
//! nuScenes-style tables), and `Frame`, one scan in the base frame with its boxes.

use std::path::{Path, PathBuf};

use crate::box3d::Box3d;
use crate::calibration::{Calibration, Lidar};
use crate::cloud::{CloudFormat, parse_cloud};
use crate::error::{DataError, ErrorKind, Result};
use crate::kitti::{CameraView, KittiOptions};
use crate::labels::{Label, read_labels};
use crate::nuscenes::NuscenesOptions;
use crate::pcd::{NonFinite, read_pcd};
use crate::rigid::Rigid;
use crate::split::{DEFAULT_VAL_SEQUENCES, Layout, Split, select_sequences};

/// The layout a dataset's files are in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum DatasetFormat {
    /// A JRDB tree: two Velodynes' PCDs per frame, `labels_3d` JSON, `defaults.yaml`.
    #[default]
    Jrdb,
    /// KITTI object: `velodyne/*.bin`, `label_2/*.txt`, `calib/*.txt`, `ImageSets/*.txt`.
    Kitti,
    /// nuScenes-style tables (nuScenes v1.0, Lyft level 5): JSON tables and LIDAR_TOP `.pcd.bin`.
    Nuscenes,
}

impl std::fmt::Display for DatasetFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            DatasetFormat::Jrdb => "jrdb",
            DatasetFormat::Kitti => "kitti",
            DatasetFormat::Nuscenes => "nuscenes",
        })
    }
}

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
    /// The files' layout.
    pub format: DatasetFormat,
    /// KITTI's settings (read when `format` is `kitti`).
    pub kitti: KittiOptions,
    /// nuScenes' settings (read when `format` is `nuscenes`).
    pub nuscenes: NuscenesOptions,
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
            format: DatasetFormat::Jrdb,
            kitti: KittiOptions::default(),
            nuscenes: NuscenesOptions::default(),
            split: Split::Train,
            val_sequences: DEFAULT_VAL_SEQUENCES.map(String::from).to_vec(),
            sequences: None,
            non_finite: NonFinite::Drop,
            on_bad_frame: OnBadFrame::Fail,
            require_labels: true,
        }
    }
}

/// Where a frame's points come from and how they reach the base frame.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameSource {
    /// JRDB: the two Velodynes' PCDs, merged `[upper, lower]` by the tree's calibration.
    Jrdb {
        /// Upper cloud file.
        upper: PathBuf,
        /// Lower cloud file.
        lower: PathBuf,
    },
    /// One cloud file (KITTI `.bin`, nuScenes `.pcd.bin`) moved into the base frame, and kept
    /// only where a camera sees when the dataset labels only its view.
    Cloud {
        /// The file.
        path: PathBuf,
        /// Its format (the dataset's, whatever the file's name says).
        format: CloudFormat,
        /// Its sensor frame → the base frame.
        to_base: Rigid,
        /// The camera whose view alone is labelled (KITTI), if the points are cropped to it.
        view: Option<CameraView>,
    },
}

/// Where a frame's files are and its labels (read once when the dataset opens).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRef {
    /// Sequence name.
    pub sequence: String,
    /// Frame name without extension (`000123`).
    pub name: String,
    /// Where its points are.
    pub source: FrameSource,
    /// Its pedestrian labels in the base frame (empty when the frame has none).
    pub labels: Vec<Label>,
    /// Boxes of objects that are neither people nor background to the evaluator (KITTI's
    /// `Cyclist`, nuScenes' strollers and wheelchairs): a detection on one counts neither way.
    pub ignored: Vec<Box3d>,
    /// Whether the labels' `num_points` is counted from the cloud when the frame loads (the
    /// format does not state it).
    pub count_points: bool,
}

impl FrameRef {
    /// The cloud files it reads (JRDB: upper, then lower).
    pub fn cloud_files(&self) -> Vec<&Path> {
        match &self.source {
            FrameSource::Jrdb { upper, lower } => vec![upper, lower],
            FrameSource::Cloud { path, .. } => vec![path],
        }
    }
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
    /// Boxes the evaluator ignores (see [`FrameRef::ignored`]); not trained on as people.
    pub ignored: Vec<Box3d>,
}

/// The frames of one split of a dataset.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The folder the frames were found in (a JRDB tree's resolved root).
    pub root: PathBuf,
    /// The files' layout.
    pub format: DatasetFormat,
    /// A JRDB tree's LiDAR → base transforms (`None` for the other layouts).
    pub calibration: Option<Calibration>,
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

impl Dataset {
    /// Appends another dataset's frames (trained on together); two JRDB trees must share one
    /// calibration, which merges every frame's two clouds.
    pub fn append(&mut self, other: Dataset) -> Result<()> {
        if let (Some(a), Some(b)) = (self.calibration, other.calibration)
            && a != b
        {
            return Err(DataError::new(Layout { root: other.root.clone() }.calibration_file(), ErrorKind::Mismatch(format!("calibration differs from {}'s; trees trained on together must share one", self.root.display()))));
        }
        self.calibration = self.calibration.or(other.calibration);
        self.frames.extend(other.frames);
        self.sequences.extend(other.sequences);
        Ok(())
    }

    /// Opens a dataset in `cfg.format` and lists the frames of `cfg.split`.
    pub fn open(dir: &Path, cfg: &DatasetConfig) -> Result<Self> {
        let (frames, sequences) = match cfg.format {
            DatasetFormat::Jrdb => return Self::open_jrdb(dir, cfg),
            DatasetFormat::Kitti => crate::kitti::list_frames(dir, cfg)?,
            DatasetFormat::Nuscenes => crate::nuscenes::list_frames(dir, cfg)?,
        };
        Ok(Self { root: dir.to_path_buf(), format: cfg.format, calibration: None, frames, sequences, non_finite: cfg.non_finite })
    }

    /// A JRDB tree (a plain root or one holding `train_dataset_with_activity/`).
    fn open_jrdb(dir: &Path, cfg: &DatasetConfig) -> Result<Self> {
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
        Ok(Self { root: layout.root, format: DatasetFormat::Jrdb, calibration: Some(calibration), frames, sequences, non_finite: cfg.non_finite })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether there are no frames.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Reads frame `i` into the base frame (a JRDB frame's two clouds merged `[upper, lower]`).
    pub fn load(&self, i: usize) -> Result<Frame> {
        let r = &self.frames[i];
        let (points, n_upper, dropped_non_finite) = match &r.source {
            FrameSource::Jrdb { upper, lower } => {
                let calibration = self.calibration.unwrap_or_default();
                let up = read_pcd(upper, self.non_finite)?;
                let lo = read_pcd(lower, self.non_finite)?;
                let (tu, tl) = (calibration.lidar(Lidar::Upper), calibration.lidar(Lidar::Lower));
                let mut points = Vec::with_capacity(up.xyz.len() + lo.xyz.len());
                points.extend(up.xyz.iter().map(|&p| tu.to_base(p)));
                points.extend(lo.xyz.iter().map(|&p| tl.to_base(p)));
                (points, up.xyz.len(), up.dropped_non_finite + lo.dropped_non_finite)
            }
            FrameSource::Cloud { path, format, to_base, view } => {
                let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
                let cloud = parse_cloud(&bytes, *format).map_err(|kind| DataError::new(path, kind))?;
                let mut points: Vec<[f32; 3]> = cloud.points.iter().map(|&p| to_base.apply_f32(p)).collect();
                if let Some(view) = view {
                    points.retain(|&p| view.sees(p));
                }
                let n = points.len();
                (points, n, cloud.dropped_non_finite)
            }
        };
        let num_points = if r.count_points {
            r.labels.iter().map(|l| l.bbox.count_inside(&points) as i64).collect()
        } else {
            r.labels.iter().map(|l| l.num_points).collect()
        };
        Ok(Frame {
            sequence: r.sequence.clone(),
            name: r.name.clone(),
            n_upper,
            points,
            dropped_non_finite,
            boxes: r.labels.iter().map(|l| l.bbox).collect(),
            num_points,
            label_ids: r.labels.iter().map(|l| l.id.clone()).collect(),
            ignored: r.ignored.clone(),
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
        out.push(FrameRef { sequence: seq.to_string(), name, source: FrameSource::Jrdb { upper, lower }, labels, ignored: Vec::new(), count_points: false });
    }
    Ok(out)
}
