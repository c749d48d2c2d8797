//! Detections as an MCAP that Foxglove and Lichtblick open: the clouds they were found in (a
//! recording's messages copied as they were) and, per frame, a `foxglove.SceneUpdate` on
//! `/pmunet/people` (JSON): a cube per person and its score as text above it, in the cloud's
//! frame id at its header's stamp.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use data_jrdb::pointcloud2::Stamp;
use serde_json::json;

use crate::detect::BoxRecord;
use crate::recording::Channel;

/// The topic of the people.
pub const PEOPLE_TOPIC: &str = "/pmunet/people";

/// The part of Foxglove's `SceneUpdate` schema the writer fills (the viewers pick their panel by
/// the schema's name and read the message as JSON).
const SCENE_UPDATE_SCHEMA: &str = r#"{
  "title": "foxglove.SceneUpdate",
  "description": "An update to the entities displayed in a 3D scene (the fields pmunet writes)",
  "type": "object",
  "properties": {
    "deletions": { "type": "array", "items": { "type": "object" } },
    "entities": {
      "type": "array",
      "items": {
        "type": "object",
        "properties": {
          "timestamp": { "type": "object", "properties": { "sec": { "type": "integer" }, "nsec": { "type": "integer" } } },
          "frame_id": { "type": "string" },
          "id": { "type": "string" },
          "lifetime": { "type": "object", "properties": { "sec": { "type": "integer" }, "nsec": { "type": "integer" } } },
          "frame_locked": { "type": "boolean" },
          "cubes": { "type": "array", "items": { "type": "object" } },
          "texts": { "type": "array", "items": { "type": "object" } }
        }
      }
    }
  }
}"#;

/// An MCAP being written: clouds copied in, people added frame by frame.
pub struct SceneWriter {
    path: PathBuf,
    w: mcap::Writer<BufWriter<std::fs::File>>,
    people: u16,
    /// Output channels by (topic, encoding): a `.bag` and an `.mcap` on one topic get two.
    clouds: BTreeMap<(String, String), u16>,
    sequence: u32,
}

impl SceneWriter {
    /// Creates `path`.
    pub fn create(path: &Path) -> Result<Self> {
        let file = std::fs::File::create(path).with_context(|| format!("{}: creating", path.display()))?;
        let mut w = mcap::WriteOptions::new().create(BufWriter::new(file)).with_context(|| format!("{}: starting the MCAP", path.display()))?;
        let schema = w.add_schema("foxglove.SceneUpdate", "jsonschema", SCENE_UPDATE_SCHEMA.as_bytes())?;
        let people = w.add_channel(schema, PEOPLE_TOPIC, "json", &BTreeMap::new())?;
        Ok(SceneWriter { path: path.to_path_buf(), w, people, clouds: BTreeMap::new(), sequence: 0 })
    }

    /// Copies a recording's message, on a channel like its own.
    pub fn copy(&mut self, channel: &Channel, log_time: u64, publish_time: u64, data: &[u8]) -> Result<()> {
        let key = (channel.topic.clone(), channel.message_encoding.clone());
        let id = match self.clouds.get(&key) {
            Some(&id) => id,
            None => {
                let schema = match &channel.schema {
                    Some((name, encoding, text)) => self.w.add_schema(name, encoding, text)?,
                    None => 0,
                };
                let id = self.w.add_channel(schema, &channel.topic, &channel.message_encoding, &BTreeMap::new())?;
                self.clouds.insert(key, id);
                id
            }
        };
        self.sequence += 1;
        let header = mcap::records::MessageHeader { channel_id: id, sequence: self.sequence, log_time, publish_time };
        self.w.write_to_known_channel(&header, data).with_context(|| format!("{}: writing", self.path.display()))
    }

    /// A frame's people: a cube per box (its heading as a rotation about z) and its score.
    pub fn people(&mut self, log_time: u64, stamp: Stamp, frame_id: &str, boxes: &[BoxRecord]) -> Result<()> {
        let time = json!({ "sec": stamp.sec, "nsec": stamp.nanosec });
        let pose = |b: &BoxRecord, dz: f64| {
            json!({ "position": { "x": b.x, "y": b.y, "z": b.z + dz }, "orientation": { "x": 0.0, "y": 0.0, "z": (b.yaw / 2.0).sin(), "w": (b.yaw / 2.0).cos() } })
        };
        let cubes: Vec<_> = boxes.iter().map(|b| json!({ "pose": pose(b, 0.0), "size": { "x": b.l, "y": b.w, "z": b.h }, "color": { "r": 1.0, "g": 0.25, "b": 0.2, "a": 0.45 } })).collect();
        let texts: Vec<_> = boxes
            .iter()
            .map(|b| json!({ "pose": pose(b, b.h / 2.0 + 0.2), "billboard": true, "font_size": 14.0, "scale_invariant": true, "color": { "r": 1.0, "g": 1.0, "b": 1.0, "a": 1.0 }, "text": format!("{:.2}", b.score) }))
            .collect();
        let update = json!({
            "deletions": [],
            "entities": [{ "timestamp": time, "frame_id": frame_id, "id": "people", "lifetime": { "sec": 0, "nsec": 0 }, "frame_locked": false, "metadata": [], "arrows": [], "cubes": cubes, "spheres": [], "cylinders": [], "lines": [], "triangles": [], "texts": texts, "models": [] }]
        });
        self.sequence += 1;
        let header = mcap::records::MessageHeader { channel_id: self.people, sequence: self.sequence, log_time, publish_time: log_time };
        self.w.write_to_known_channel(&header, &serde_json::to_vec(&update)?).with_context(|| format!("{}: writing", self.path.display()))
    }

    /// Writes the summary and closes the file.
    pub fn finish(mut self) -> Result<()> {
        self.w.finish().with_context(|| format!("{}: finishing", self.path.display()))?;
        Ok(())
    }
}
