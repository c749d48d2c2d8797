//! `labels/labels_3d/<seq>.json`: the pedestrian boxes of every frame of a sequence.
//!
//! Shape: `{"labels": {"000000.pcd": [{"label_id": "pedestrian:46", "box": {cx, cy, cz, l, w, h,
//! rot_z}, "attributes": {"num_points": n, ...}, ...}]}}`. Only `pedestrian:*` labels are kept.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::{Map, Value, json};

use crate::box3d::Box3d;
use crate::error::{DataError, ErrorKind, Result};

/// One labelled pedestrian.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Label {
    /// The `label_id`, e.g. `pedestrian:46` (stable across the frames of a sequence).
    pub id: String,
    /// The box in the base frame.
    pub bbox: Box3d,
    /// LiDAR points inside the box according to the annotation (`attributes.num_points`).
    pub num_points: i64,
    /// `observation_angle` (−1 where the file has none): KITTI's `alpha` column when the labels
    /// are converted for the official evaluator, which does not score it.
    pub observation_angle: f64,
}

/// Labels of one sequence, by PCD file name (`000123.pcd`).
pub type SequenceLabels = BTreeMap<String, Vec<Label>>;

/// Reads a `labels_3d` JSON file.
pub fn read_labels(path: &Path) -> Result<SequenceLabels> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    parse_labels_json(&text, path)
}

/// Parses the text of a `labels_3d` JSON file; errors name `path`.
pub fn parse_labels_json(text: &str, path: &Path) -> Result<SequenceLabels> {
    let doc: Value = serde_json::from_str(text).map_err(|e| DataError::new(path, ErrorKind::Parse(e.to_string())))?;
    parse_labels(&doc).map_err(|(key, what)| DataError::key(path, key, what))
}

fn parse_labels(doc: &Value) -> std::result::Result<SequenceLabels, (String, String)> {
    let labels = doc
        .get("labels")
        .ok_or(("labels".to_string(), "missing".to_string()))?
        .as_object()
        .ok_or(("labels".to_string(), "is not an object".to_string()))?;
    let mut out = SequenceLabels::new();
    for (frame, list) in labels {
        let at = format!("labels[{frame:?}]");
        let list = list.as_array().ok_or((at.clone(), "is not a list".to_string()))?;
        let mut kept = Vec::new();
        for (i, item) in list.iter().enumerate() {
            let at = format!("{at}[{i}]");
            let id = item
                .get("label_id")
                .and_then(Value::as_str)
                .ok_or((format!("{at}.label_id"), "missing or not a string".to_string()))?;
            if !id.starts_with("pedestrian:") {
                continue;
            }
            let b = item.get("box").and_then(Value::as_object).ok_or((format!("{at}.box"), "missing or not an object".to_string()))?;
            let num = |k: &str| -> std::result::Result<f64, (String, String)> {
                let v = b.get(k).ok_or((format!("{at}.box.{k}"), "missing".to_string()))?;
                let x = v.as_f64().ok_or((format!("{at}.box.{k}"), format!("`{v}` is not a number")))?;
                if !x.is_finite() {
                    return Err((format!("{at}.box.{k}"), "is not finite".to_string()));
                }
                Ok(x)
            };
            let bbox = Box3d { cx: num("cx")?, cy: num("cy")?, cz: num("cz")?, l: num("l")?, w: num("w")?, h: num("h")?, rot_z: num("rot_z")? };
            let np = item
                .get("attributes")
                .and_then(|a| a.get("num_points"))
                .ok_or((format!("{at}.attributes.num_points"), "missing".to_string()))?;
            let num_points = np
                .as_i64()
                .or_else(|| np.as_f64().filter(|f| f.fract() == 0.0).map(|f| f as i64))
                .ok_or((format!("{at}.attributes.num_points"), format!("`{np}` is not an integer")))?;
            let observation_angle = match item.get("observation_angle") {
                None | Some(Value::Null) => -1.0,
                Some(v) => v.as_f64().ok_or((format!("{at}.observation_angle"), format!("`{v}` is not a number")))?,
            };
            kept.push(Label { id: id.to_string(), bbox, num_points, observation_angle });
        }
        out.insert(frame.clone(), kept);
    }
    Ok(out)
}

/// Writes a `labels_3d` JSON file with the keys real JRDB files carry.
pub fn write_labels(path: &Path, labels: &SequenceLabels) -> Result<()> {
    let mut map = Map::new();
    for (frame, list) in labels {
        let items: Vec<Value> = list
            .iter()
            .map(|l| {
                let b = &l.bbox;
                json!({
                    "label_id": l.id,
                    "box": {"cx": b.cx, "cy": b.cy, "cz": b.cz, "l": b.l, "w": b.w, "h": b.h, "rot_z": b.rot_z},
                    "attributes": {"num_points": l.num_points, "distance": b.bev_range(), "no_eval": false,
                                   "interpolated": false, "occlusion": if l.num_points >= 10 { "Fully_visible" } else { "Severely_occluded" }},
                    "observation_angle": l.observation_angle,
                    "file_id": frame,
                })
            })
            .collect();
        map.insert(frame.clone(), Value::Array(items));
    }
    let text = serde_json::to_string(&json!({ "labels": map })).expect("JSON of plain values");
    std::fs::write(path, text).map_err(|e| DataError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_pedestrians_and_names_bad_keys() {
        let doc = json!({"labels": {"000000.pcd": [
            {"label_id": "pedestrian:1", "box": {"cx": 1, "cy": 2.0, "cz": 0.1, "l": 0.5, "w": 0.6, "h": 1.7, "rot_z": -0.3},
             "attributes": {"num_points": 42}},
            {"label_id": "car:3", "box": {}, "attributes": {}}
        ], "000001.pcd": []}});
        let l = parse_labels(&doc).unwrap();
        assert_eq!(l["000000.pcd"].len(), 1);
        assert_eq!(l["000000.pcd"][0].num_points, 42);
        assert_eq!(l["000000.pcd"][0].bbox.rot_z, -0.3);
        assert_eq!(l["000000.pcd"][0].observation_angle, -1.0, "absent");
        assert!(l["000001.pcd"].is_empty());
        let bad = json!({"labels": {"000000.pcd": [{"label_id": "pedestrian:1", "box": {"cx": 1}, "attributes": {"num_points": 1}}]}});
        let (key, _) = parse_labels(&bad).unwrap_err();
        assert_eq!(key, "labels[\"000000.pcd\"][0].box.cy");
    }
}
