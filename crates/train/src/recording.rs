//! Recordings: MCAP files (ROS 2 bags' default storage, and what Foxglove records) holding
//! `sensor_msgs/msg/PointCloud2` messages, read message by message through the `mcap` crate and
//! decoded by `data_jrdb::pointcloud2`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use data_jrdb::cloud::ReadLimits;
use data_jrdb::pointcloud2::{PointCloud2, decode_cdr};

/// The ROS 2 schema name of a point cloud.
pub const POINTCLOUD2: &str = "sensor_msgs/msg/PointCloud2";

/// One topic of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Topic {
    /// Its name (`/velodyne_points`).
    pub name: String,
    /// Its schema's name (`sensor_msgs/msg/PointCloud2`), empty without one.
    pub schema: String,
    /// The messages' encoding (`cdr`).
    pub encoding: String,
    /// Messages on it, where the file's summary counts them.
    pub messages: Option<u64>,
}

/// Whether `path` is a recording this reads (by its name).
pub fn is_recording(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// An MCAP file mapped into memory (a recording of hours is not read into it).
pub struct Recording {
    path: PathBuf,
    map: memmap2::Mmap,
}

impl Recording {
    /// Opens `path`.
    pub fn open(path: &Path) -> Result<Self> {
        let file = std::fs::File::open(path).with_context(|| format!("{}: opening the recording", path.display()))?;
        // SAFETY: the map is only read; a file changed while it is read gives wrong messages or
        // a decoding error, as reading it piecewise would.
        let map = unsafe { memmap2::Mmap::map(&file) }.with_context(|| format!("{}: mapping the recording", path.display()))?;
        Ok(Recording { path: path.to_path_buf(), map })
    }

    /// Its topics, from the summary section when the file has one, else by reading it through.
    pub fn topics(&self) -> Result<Vec<Topic>> {
        let mut topics: Vec<Topic> = Vec::new();
        if let Some(summary) = mcap::Summary::read(&self.map).ok().flatten().filter(|s| !s.channels.is_empty()) {
            let counts = summary.stats.as_ref().map(|s| &s.channel_message_counts);
            for (id, ch) in &summary.channels {
                topics.push(Topic {
                    name: ch.topic.clone(),
                    schema: ch.schema.as_ref().map_or_else(String::new, |s| s.name.clone()),
                    encoding: ch.message_encoding.clone(),
                    messages: counts.and_then(|c| c.get(id).copied()),
                });
            }
        } else {
            for m in self.stream()? {
                let m = m.with_context(|| format!("{}: reading its messages", self.path.display()))?;
                match topics.iter_mut().find(|t| t.name == m.channel.topic) {
                    Some(t) => *t.messages.get_or_insert(0) += 1,
                    None => topics.push(Topic {
                        name: m.channel.topic.clone(),
                        schema: m.channel.schema.as_ref().map_or_else(String::new, |s| s.name.clone()),
                        encoding: m.channel.message_encoding.clone(),
                        messages: Some(1),
                    }),
                }
            }
        }
        topics.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(topics)
    }

    fn stream(&self) -> Result<mcap::MessageStream<'_>> {
        mcap::MessageStream::new(&self.map).map_err(|e| anyhow::anyhow!("{}: not an MCAP file this reads: {e}", self.path.display()))
    }

    /// The point clouds on `topic` in the file's order, decoded, or why one could not be (the
    /// others still come).
    pub fn clouds<'a>(&'a self, topic: &'a str, limits: &'a ReadLimits) -> Result<impl Iterator<Item = Result<CloudMessage<'a>>> + 'a> {
        let topics = self.topics()?;
        let Some(t) = topics.iter().find(|t| t.name == topic) else {
            bail!("{}: no topic `{topic}` (topics: {})", self.path.display(), topics.iter().map(|t| format!("{} [{}]", t.name, t.schema)).collect::<Vec<_>>().join(", "));
        };
        if t.schema != POINTCLOUD2 || t.encoding != "cdr" {
            bail!("{}: topic `{topic}` holds {} in {} encoding; this reads {POINTCLOUD2} in cdr", self.path.display(), t.schema, t.encoding);
        }
        let path = &self.path;
        Ok(self.stream()?.filter_map(move |m| match m {
            Err(e) => Some(Err(anyhow::anyhow!("{}: reading its messages: {e}", path.display()))),
            Ok(m) if m.channel.topic != topic => None,
            Ok(m) => Some(match decode_cdr(&m.data, limits) {
                Ok(cloud) => Ok(CloudMessage { cloud, log_time: m.log_time, publish_time: m.publish_time, channel: m.channel.clone(), data: m.data }),
                Err(e) => Err(anyhow::anyhow!("{}: message {} on {topic}: {e}", path.display(), m.sequence)),
            }),
        }))
    }
}

/// A point-cloud message of a recording: decoded, and as it was (to be copied into an output).
pub struct CloudMessage<'a> {
    /// The decoded cloud.
    pub cloud: PointCloud2,
    /// The recording's log time (ns).
    pub log_time: u64,
    /// The publish time (ns).
    pub publish_time: u64,
    /// Its channel (topic, schema, encoding).
    pub channel: std::sync::Arc<mcap::Channel<'a>>,
    /// The serialized message.
    pub data: std::borrow::Cow<'a, [u8]>,
}
