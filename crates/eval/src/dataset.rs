//! Pairing ground truth with detections, from either format, into [`Frame`]s.
//!
//! The frames evaluated are the ground truth's (as in the official tool): every GT frame needs
//! detections (an empty file or list is fine), extra detection frames are not evaluated.
//! - KITTI layout: `GT/<sequence>/<frame>.txt` and `DET/<sequence>/<frame>.txt`; `.txt` files
//!   directly in the folder are frames of one unnamed sequence (what `train detect` writes for
//!   plain files: `OUT/kitti/<name>.txt`).
//! - JRDB layout: `GT/<sequence>.json` (`labels_3d`) or one such file, and
//!   `DET/<sequence>.json` (pmunet detection files, see [`crate::jrdb`]) or one such file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::ap::Frame;
use crate::error::{EvalError, Result};
use crate::jrdb;
use crate::kitti::{self, FileKind, KittiObject};

/// On-disk layout of a GT or detection set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// The official KITTI-style txt tree `DIR/<sequence>/<frame>.txt`.
    Kitti,
    /// JRDB `labels_3d` JSON (GT) or pmunet detection JSON, one file per sequence.
    Jrdb,
}

fn read_dir_sorted(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| EvalError::io(dir, e))?
        .map(|e| e.map(|e| e.path()).map_err(|e| EvalError::io(dir, e)))
        .collect::<Result<_>>()?;
    v.sort();
    Ok(v)
}

fn has_ext(p: &Path, ext: &str) -> bool {
    p.extension().is_some_and(|e| e == ext)
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Guesses the layout: a `.json` file or a folder of `.json` files is JRDB, a folder of
/// sequence folders or of `.txt` files is KITTI.
pub fn detect_format(path: &Path) -> Result<Format> {
    if path.is_file() {
        return if has_ext(path, "json") {
            Ok(Format::Jrdb)
        } else {
            Err(EvalError::Layout {
                path: path.into(),
                message: "expected a .json file or a folder".into(),
            })
        };
    }
    let entries = read_dir_sorted(path)?;
    if entries.iter().any(|p| p.is_dir()) {
        Ok(Format::Kitti)
    } else if entries.iter().any(|p| has_ext(p, "json")) {
        Ok(Format::Jrdb)
    } else if entries.iter().any(|p| has_ext(p, "txt")) {
        Ok(Format::Kitti)
    } else {
        Err(EvalError::Layout {
            path: path.into(),
            message: "neither .txt files or sequence folders of them (kitti) nor .json files (jrdb); pass --format".into(),
        })
    }
}

/// Frames of one side: sequence → frame → (where it came from, lines).
type Side = BTreeMap<String, BTreeMap<String, (PathBuf, Vec<KittiObject>)>>;

fn json_files(path: &Path) -> Result<Vec<PathBuf>> {
    if path.is_file() {
        Ok(vec![path.to_path_buf()])
    } else {
        Ok(read_dir_sorted(path)?
            .into_iter()
            .filter(|p| has_ext(p, "json") && p.is_file())
            .collect())
    }
}

/// Reads the ground truth.
fn load_gt(path: &Path, format: Format) -> Result<Side> {
    let mut side = Side::new();
    match format {
        Format::Kitti => {
            // The folder's own `.txt` files are the unnamed sequence "": `DET/<frame>.txt` pairs with them.
            let entries = read_dir_sorted(path)?;
            let sequences = std::iter::once((String::new(), path.to_path_buf()))
                .chain(entries.iter().filter(|p| p.is_dir()).map(|d| (d.file_name().unwrap().to_string_lossy().into_owned(), d.clone())));
            for (name, dir) in sequences {
                let files: Vec<PathBuf> = read_dir_sorted(&dir)?.into_iter().filter(|p| p.is_file() && has_ext(p, "txt")).collect();
                if files.is_empty() {
                    continue;
                }
                let seq = side.entry(name).or_default();
                for f in files {
                    let objs = kitti::read_file(&f, FileKind::GroundTruth)?;
                    seq.insert(stem(&f), (f, objs));
                }
            }
        }
        Format::Jrdb => {
            for f in json_files(path)? {
                let labels = jrdb::read_labels_3d(&f)?;
                let seq = side.entry(stem(&f)).or_default();
                for (frame, l) in labels {
                    seq.insert(frame.clone(), (f.join(&frame), jrdb::labels_to_kitti(&l)));
                }
            }
        }
    }
    if side.values().all(|s| s.is_empty()) {
        return Err(EvalError::Layout {
            path: path.into(),
            message: "no ground-truth frames found".into(),
        });
    }
    Ok(side)
}

/// Reads GT and detections and pairs them frame by frame, in sequence and frame order.
///
/// A GT frame without detections is an error naming it, unless `missing_as_empty`.
pub fn load(
    gt: &Path,
    gt_format: Format,
    det: &Path,
    det_format: Format,
    missing_as_empty: bool,
) -> Result<Vec<Frame>> {
    let gt_side = load_gt(gt, gt_format)?;
    let mut frames = Vec::new();
    // Detection JSON files are read once per sequence.
    let mut det_json: BTreeMap<String, Option<(PathBuf, jrdb::DetectionFile)>> = BTreeMap::new();
    let det_json_files: Vec<PathBuf> = if det_format == Format::Jrdb && det.is_file() {
        vec![det.to_path_buf()]
    } else {
        Vec::new()
    };
    for (seq, seq_frames) in &gt_side {
        for (name, (gt_origin, gt_objs)) in seq_frames {
            let dets = match det_format {
                Format::Kitti => {
                    let p = det.join(seq).join(format!("{name}.txt"));
                    if p.is_file() {
                        Some(kitti::read_file(&p, FileKind::Detections)?)
                    } else if missing_as_empty {
                        Some(Vec::new())
                    } else {
                        return Err(EvalError::MissingDetections {
                            gt: gt_origin.clone(),
                            expected: p,
                        });
                    }
                }
                Format::Jrdb => {
                    let entry = match det_json.get(seq) {
                        Some(e) => e,
                        None => {
                            let file = if det.is_file() {
                                // A single detection file serves the sequence it is named for.
                                det_json_files.iter().find(|p| stem(p) == *seq).cloned()
                            } else {
                                let p = det.join(format!("{seq}.json"));
                                p.is_file().then_some(p)
                            };
                            let loaded = match file {
                                Some(p) => Some((p.clone(), jrdb::read_detections(&p)?)),
                                None => None,
                            };
                            det_json.entry(seq.clone()).or_insert(loaded)
                        }
                    };
                    match entry.as_ref().and_then(|(_, f)| f.detections.get(name)) {
                        Some(d) => Some(jrdb::detections_to_kitti(d)),
                        None if missing_as_empty => Some(Vec::new()),
                        None => {
                            let expected = match entry {
                                Some((p, _)) => {
                                    PathBuf::from(format!("frame \"{name}\" in {}", p.display()))
                                }
                                None => {
                                    if det.is_file() {
                                        det.to_path_buf()
                                    } else {
                                        det.join(format!("{seq}.json"))
                                    }
                                }
                            };
                            return Err(EvalError::MissingDetections {
                                gt: gt_origin.clone(),
                                expected,
                            });
                        }
                    }
                }
            };
            frames.push(Frame {
                sequence: seq.clone(),
                name: name.clone(),
                gt: gt_objs.clone(),
                det: dets.unwrap_or_default(),
            });
        }
    }
    Ok(frames)
}

/// Writes the GT (`kind = GroundTruth`) or detections of `frames` as the official txt tree
/// `dir/<sequence>/<frame>.txt`, so they can be fed to the official tool or the leaderboard.
pub fn write_kitti_tree(dir: &Path, frames: &[Frame], kind: FileKind) -> Result<()> {
    for f in frames {
        let objs = match kind {
            FileKind::GroundTruth => &f.gt,
            FileKind::Detections => &f.det,
        };
        kitti::write_file(
            &dir.join(&f.sequence).join(format!("{}.txt", f.name)),
            objs,
            kind,
        )?;
    }
    Ok(())
}
