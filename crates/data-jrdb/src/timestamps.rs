//! `timestamps/<seq>/frames_pc.json`: when each frame's two clouds were taken (the simulator
//! writes it for a complete tree; detection does not need it).

use std::path::Path;

use serde_json::{Value, json};

use crate::error::{DataError, Result};

/// One entry of `frames_pc.json`.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTime {
    /// `frame_id`.
    pub frame_id: u64,
    /// `timestamp` (seconds).
    pub timestamp: f64,
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
