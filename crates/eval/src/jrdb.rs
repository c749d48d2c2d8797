//! JRDB's own JSON: `labels_3d/<sequence>.json` ground truth, and pmunet's detection files.
//!
//! Ground truth (`labels/labels_3d/<sequence>.json`, JRDB's layout, docs/data.md):
//! ```json
//! {"labels": {"000000.pcd": [{"label_id": "pedestrian:46",
//!     "box": {"cx": 1.0, "cy": 2.0, "cz": 0.1, "l": 0.9, "w": 0.5, "h": 1.7, "rot_z": 0.3},
//!     "attributes": {"num_points": 57}, "observation_angle": 0.2}]}}
//! ```
//! Only `label_id`s starting with `pedestrian:` are kept (as the official converter does).
//!
//! Detections (pmunet's schema, one file per sequence, `<dir>/<sequence>.json`):
//! ```json
//! {"sequence": "bytes-cafe-2019-02-07_0",
//!  "detections": {"000000": [{"box": {"cx": 1.0, "cy": 2.0, "cz": 0.1, "l": 0.9, "w": 0.5,
//!                                     "h": 1.7, "rot_z": 0.3}, "score": 0.93}]}}
//! ```
//! Boxes are [`Box3d`] in the JRDB base frame. Frame keys may carry the `.pcd` extension of the
//! label files (`"000000.pcd"`); it is stripped. `"sequence"` is optional and, when present,
//! must equal the file stem. Frames without detections may be written as empty lists.

use std::collections::BTreeMap;
use std::path::Path;

use data_jrdb::{Box3d, Label};
use serde::{Deserialize, Serialize};

use crate::error::{EvalError, Result};
use crate::kitti::KittiObject;

/// One detection: a box and its score.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Detection {
    /// The box, JRDB base frame.
    #[serde(rename = "box")]
    pub bbox: Box3d,
    /// Confidence, higher is better.
    pub score: f64,
}

/// A pmunet detection file: all frames of one sequence.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DetectionFile {
    /// Sequence name (optional on read; equals the file stem).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence: Option<String>,
    /// Frame name (no extension) → detections.
    pub detections: BTreeMap<String, Vec<Detection>>,
}

/// `"000123.pcd"` → `"000123"`.
pub fn frame_key(name: &str) -> String {
    Path::new(name)
        .file_stem()
        .map_or_else(|| name.to_string(), |s| s.to_string_lossy().into_owned())
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| EvalError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| EvalError::json(path, &e))
}

/// Reads a `labels_3d/<sequence>.json` file with data-jrdb's reader (the one training uses):
/// frame name (no extension) → its pedestrian labels, in file order.
pub fn read_labels_3d(path: &Path) -> Result<BTreeMap<String, Vec<Label>>> {
    Ok(data_jrdb::labels::read_labels(path)?
        .into_iter()
        .map(|(k, v)| (frame_key(&k), v))
        .collect())
}

/// The KITTI lines the official converter writes for one frame's labels (the pedestrians
/// [`read_labels_3d`] keeps), in label order, with `num_points` and `observation_angle` carried
/// over.
pub fn labels_to_kitti(labels: &[Label]) -> Vec<KittiObject> {
    labels
        .iter()
        .map(|l| KittiObject::ground_truth(&l.bbox, l.num_points, l.observation_angle))
        .collect()
}

/// Reads a pmunet detection file; checks `"sequence"` against the file stem.
pub fn read_detections(path: &Path) -> Result<DetectionFile> {
    let mut file: DetectionFile = read_json(path)?;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    if let Some(seq) = file.sequence.as_ref().filter(|s| **s != stem) {
        return Err(EvalError::Layout {
            path: path.to_path_buf(),
            message: format!("\"sequence\" is `{seq}` but the file is named for `{stem}`"),
        });
    }
    file.detections = std::mem::take(&mut file.detections)
        .into_iter()
        .map(|(k, v)| (frame_key(&k), v))
        .collect();
    for (frame, dets) in &file.detections {
        if let Some(d) = dets
            .iter()
            .find(|d| d.bbox.l < 0.0 || d.bbox.w < 0.0 || d.bbox.h < 0.0)
        {
            return Err(EvalError::Layout {
                path: path.to_path_buf(),
                message: format!("frame {frame}: negative box size in {:?}", d.bbox),
            });
        }
    }
    Ok(file)
}

/// Writes a pmunet detection file (pretty-printed; floats keep full precision).
pub fn write_detections(path: &Path, file: &DetectionFile) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| EvalError::io(dir, e))?;
    }
    let text = serde_json::to_string_pretty(file).expect("detections serialize");
    std::fs::write(path, text).map_err(|e| EvalError::io(path, e))
}

/// The KITTI lines for one frame's detections (`Pedestrian`, converter mapping, score last).
pub fn detections_to_kitti(dets: &[Detection]) -> Vec<KittiObject> {
    dets.iter()
        .map(|d| KittiObject::from_box3d(&d.bbox, -1, d.score))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_json_names_line_and_column() {
        let dir = std::env::temp_dir().join(format!("eval-jrdb-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("seq.json");
        std::fs::write(
            &p,
            "{\"detections\": {\n  \"000000\": [{\"box\": {\"cx\": 1}, \"score\": 0.5}]}}",
        )
        .unwrap();
        let e = read_detections(&p).unwrap_err().to_string();
        assert!(
            e.contains("seq.json:2:") && e.contains("missing field"),
            "{e}"
        );
        std::fs::write(&p, "{\"labels\": {\"000000.pcd\": [}}").unwrap();
        let e = read_labels_3d(&p).unwrap_err().to_string();
        assert!(e.contains("seq.json") && e.contains("line 1 column 28"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
