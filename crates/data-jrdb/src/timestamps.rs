//! `timestamps/<seq>/frames_pc.json`: when each frame's two clouds were taken.

use std::path::Path;

use serde_json::{Value, json};

use crate::error::{DataError, ErrorKind, Result};

/// One entry of `frames_pc.json`.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTime {
    /// `frame_id`.
    pub frame_id: u64,
    /// `timestamp` (seconds).
    pub timestamp: f64,
}

/// Reads `frames_pc.json`.
pub fn read_timestamps(path: &Path) -> Result<Vec<FrameTime>> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))?;
    let doc: Value = serde_json::from_str(&text).map_err(|e| DataError::new(path, ErrorKind::Parse(e.to_string())))?;
    let data = doc.get("data").and_then(Value::as_array).ok_or_else(|| DataError::key(path, "data", "missing or not a list"))?;
    data.iter()
        .enumerate()
        .map(|(i, d)| {
            let frame_id = d.get("frame_id").and_then(Value::as_u64).ok_or_else(|| DataError::key(path, format!("data[{i}].frame_id"), "missing or not an integer"))?;
            let timestamp = d.get("timestamp").and_then(Value::as_f64).ok_or_else(|| DataError::key(path, format!("data[{i}].timestamp"), "missing or not a number"))?;
            Ok(FrameTime { frame_id, timestamp })
        })
        .collect()
}

/// Writes `frames_pc.json` for frames `000000.pcd, ...` of `seq`.
pub fn write_timestamps(path: &Path, seq: &str, times: &[FrameTime]) -> Result<()> {
    let data: Vec<Value> = times
        .iter()
        .map(|t| {
            let name = format!("{:06}.pcd", t.frame_id);
            json!({"frame_id": t.frame_id, "timestamp": t.timestamp, "pointclouds": [
                {"name": "upper_velodyne", "url": format!("pointclouds/upper_velodyne/{seq}/{name}"), "timestamp": t.timestamp},
                {"name": "lower_velodyne", "url": format!("pointclouds/lower_velodyne/{seq}/{name}"), "timestamp": t.timestamp},
            ]})
        })
        .collect();
    let text = serde_json::to_string(&json!({ "data": data })).expect("JSON of plain values");
    std::fs::write(path, text).map_err(|e| DataError::io(path, e))
}
