//! Recordings holding `sensor_msgs/PointCloud2` messages, read message by message: MCAP (ROS 2
//! bags' default storage, and what Foxglove records) through the `mcap` crate, ROS 2 bags' SQLite
//! storage (`.db3`) through `rusqlite`, and ROS 1 bags (`.bag`, chunks bz2- or lz4-compressed)
//! through `rosbag`. The messages are decoded by `data_jrdb::pointcloud2` (CDR for ROS 2, ROS 1's
//! own serialization for `.bag`).

use std::borrow::Cow;
use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, anyhow, bail};
use data_jrdb::cloud::ReadLimits;
use data_jrdb::pointcloud2::{PointCloud2, decode_cdr, decode_ros1};

/// The ROS 2 type name of a point cloud.
pub const POINTCLOUD2: &str = "sensor_msgs/msg/PointCloud2";

/// The ROS 1 type name of a point cloud.
pub const POINTCLOUD2_ROS1: &str = "sensor_msgs/PointCloud2";

/// `sensor_msgs/msg/PointCloud2`'s definition as MCAP's `ros2msg` schemas give it: what a cloud
/// copied from a `.db3` (which need not store definitions) is written with.
const POINTCLOUD2_ROS2MSG: &str = "std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool is_bigendian
uint32 point_step
uint32 row_step
uint8[] data
bool is_dense
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: sensor_msgs/PointField
uint8 INT8=1
uint8 UINT8=2
uint8 INT16=3
uint8 UINT16=4
uint8 INT32=5
uint8 UINT32=6
uint8 FLOAT32=7
uint8 FLOAT64=8
string name
uint32 offset
uint8 datatype
uint32 count";

/// One topic of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Topic {
    /// Its name (`/velodyne_points`).
    pub name: String,
    /// Its type (`sensor_msgs/msg/PointCloud2`; ROS 1: `sensor_msgs/PointCloud2`), empty
    /// without one.
    pub schema: String,
    /// The messages' serialization (`cdr`; `ros1`).
    pub encoding: String,
    /// Messages on it, where the file counts them.
    pub messages: Option<u64>,
}

/// The storage formats read, by file name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordingFormat {
    /// MCAP (`.mcap`).
    Mcap,
    /// A ROS 2 bag's SQLite storage (`.db3`).
    Db3,
    /// A ROS 1 bag (`.bag`).
    Ros1Bag,
}

impl RecordingFormat {
    /// The format a file's name says, if it is a recording.
    pub fn of(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_string_lossy().to_ascii_lowercase();
        match ext.as_str() {
            "mcap" => Some(Self::Mcap),
            "db3" => Some(Self::Db3),
            "bag" => Some(Self::Ros1Bag),
            _ => None,
        }
    }
}

/// Whether `path` is a recording this reads (by its name).
pub fn is_recording(path: &Path) -> bool {
    RecordingFormat::of(path).is_some()
}

/// The storage files of a ROS 2 bag folder (`metadata.yaml` beside `.db3` or `.mcap` files), in
/// order; empty when `dir` is not one.
pub fn bag_folder_files(dir: &Path) -> Result<Vec<PathBuf>> {
    if !dir.join("metadata.yaml").is_file() {
        return Ok(Vec::new());
    }
    let mut files = Vec::new();
    for e in std::fs::read_dir(dir).with_context(|| format!("{}: listing the bag folder", dir.display()))? {
        let p = e.with_context(|| format!("{}: listing the bag folder", dir.display()))?.path();
        if matches!(RecordingFormat::of(&p), Some(RecordingFormat::Mcap | RecordingFormat::Db3)) {
            files.push(p);
        }
    }
    // rosbag2 numbers split files `<bag>_0.db3`, `<bag>_1.db3`, …: `_10` after `_9`.
    files.sort_by_key(|p| {
        let stem = p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let digits = stem.len() - stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let (head, tail) = stem.split_at(stem.len() - digits);
        (head.to_string(), tail.parse::<u64>().unwrap_or(0), p.clone())
    });
    Ok(files)
}

/// How a topic's messages are stored, for copying them into an MCAP as they were.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Channel {
    /// The topic.
    pub topic: String,
    /// The schema's name, encoding (`ros2msg`, `ros1msg`) and text, if known.
    pub schema: Option<(String, String, Vec<u8>)>,
    /// The messages' encoding (`cdr`, `ros1`).
    pub message_encoding: String,
}

/// A point-cloud message of a recording: decoded, and as it was (to be copied into an output).
pub struct CloudMessage<'a> {
    /// The decoded cloud.
    pub cloud: PointCloud2,
    /// The recording's log time (ns).
    pub log_time: u64,
    /// The publish time (ns; the log time where the storage has no other).
    pub publish_time: u64,
    /// Its channel.
    pub channel: Arc<Channel>,
    /// The serialized message.
    pub data: Cow<'a, [u8]>,
}

enum Storage {
    /// The file mapped into memory (a recording of hours is not read into it).
    Mcap(memmap2::Mmap),
    Db3(rusqlite::Connection),
    Ros1(rosbag::RosBag),
}

/// A recording opened for reading.
pub struct Recording {
    path: PathBuf,
    storage: Storage,
}

type Messages<'a> = Box<dyn Iterator<Item = Result<CloudMessage<'a>>> + 'a>;

impl Recording {
    /// Opens `path` (its format from its name).
    pub fn open(path: &Path) -> Result<Self> {
        let format = RecordingFormat::of(path).ok_or_else(|| anyhow!("{}: not a recording (.mcap, .db3 or .bag)", path.display()))?;
        let storage = match format {
            RecordingFormat::Mcap => {
                let file = std::fs::File::open(path).with_context(|| format!("{}: opening the recording", path.display()))?;
                // SAFETY: the map is only read; a file changed while it is read gives wrong
                // messages or a decoding error, as reading it piecewise would.
                Storage::Mcap(unsafe { memmap2::Mmap::map(&file) }.with_context(|| format!("{}: mapping the recording", path.display()))?)
            }
            RecordingFormat::Db3 => {
                anyhow::ensure!(path.is_file(), "{}: no such file", path.display());
                let flags = rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX;
                Storage::Db3(rusqlite::Connection::open_with_flags(path, flags).with_context(|| format!("{}: opening the ROS 2 bag", path.display()))?)
            }
            RecordingFormat::Ros1Bag => {
                check_ros1_index(path)?;
                Storage::Ros1(rosbag::RosBag::new(path).map_err(|e| anyhow!("{}: not a ROS 1 bag this reads: {e}", path.display()))?)
            }
        };
        Ok(Recording { path: path.to_path_buf(), storage })
    }

    /// Its topics, sorted by name.
    pub fn topics(&self) -> Result<Vec<Topic>> {
        let mut topics = match &self.storage {
            Storage::Mcap(map) => self.mcap_topics(map)?,
            Storage::Db3(db) => self.db3_topics(db)?,
            Storage::Ros1(bag) => self.ros1_topics(bag)?,
        };
        topics.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(topics)
    }

    fn mcap_topics(&self, map: &[u8]) -> Result<Vec<Topic>> {
        let mut topics: Vec<Topic> = Vec::new();
        if let Some(summary) = mcap::Summary::read(map).ok().flatten().filter(|s| !s.channels.is_empty()) {
            let counts = summary.stats.as_ref().map(|s| &s.channel_message_counts);
            for (id, ch) in &summary.channels {
                let n = counts.and_then(|c| c.get(id).copied());
                // Several channels may share a topic (one per publisher): one row, their sum.
                match topics.iter_mut().find(|t| t.name == ch.topic) {
                    Some(t) => t.messages = t.messages.zip(n).map(|(a, b)| a + b),
                    None => topics.push(Topic {
                        name: ch.topic.clone(),
                        schema: ch.schema.as_ref().map_or_else(String::new, |s| s.name.clone()),
                        encoding: ch.message_encoding.clone(),
                        messages: n,
                    }),
                }
            }
        } else {
            for m in self.mcap_stream(map)? {
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
        Ok(topics)
    }

    fn db3_topics(&self, db: &rusqlite::Connection) -> Result<Vec<Topic>> {
        let sql = "SELECT t.name, t.type, t.serialization_format, (SELECT COUNT(*) FROM messages m WHERE m.topic_id = t.id) FROM topics t";
        let mut stmt = db.prepare(sql).with_context(|| format!("{}: not a ROS 2 bag's SQLite storage (its topics table)", self.path.display()))?;
        let rows = stmt.query_map([], |r| Ok(Topic { name: r.get(0)?, schema: r.get(1)?, encoding: r.get(2)?, messages: Some(r.get::<_, i64>(3)? as u64) }));
        rows.and_then(|rows| rows.collect::<rusqlite::Result<Vec<_>>>()).with_context(|| format!("{}: reading its topics", self.path.display()))
    }

    fn ros1_topics(&self, bag: &rosbag::RosBag) -> Result<Vec<Topic>> {
        let mut conns: BTreeMap<u32, (String, String)> = BTreeMap::new();
        let mut counts: BTreeMap<u32, u64> = BTreeMap::new();
        for r in bag.index_records() {
            match r.map_err(|e| anyhow!("{}: reading its index: {e}", self.path.display()))? {
                rosbag::IndexRecord::Connection(c) => {
                    // The topic the bag stores it under (what `rosbag info` shows), which a
                    // rewritten bag may have changed from the publisher's.
                    conns.insert(c.id, (c.storage_topic.to_string(), c.tp.to_string()));
                }
                rosbag::IndexRecord::ChunkInfo(info) => {
                    for e in info.entries() {
                        *counts.entry(e.conn_id).or_default() += e.count as u64;
                    }
                }
                rosbag::IndexRecord::IndexData(_) => {}
            }
        }
        // Several connections may share a topic (one per publisher).
        let mut topics: Vec<Topic> = Vec::new();
        for (id, (name, tp)) in conns {
            let n = counts.get(&id).copied().unwrap_or(0);
            match topics.iter_mut().find(|t| t.name == name) {
                Some(t) => *t.messages.get_or_insert(0) += n,
                None => topics.push(Topic { name, schema: tp, encoding: "ros1".into(), messages: Some(n) }),
            }
        }
        Ok(topics)
    }

    fn mcap_stream<'a>(&self, map: &'a [u8]) -> Result<mcap::MessageStream<'a>> {
        mcap::MessageStream::new(map).map_err(|e| anyhow!("{}: not an MCAP file this reads: {e}", self.path.display()))
    }

    /// The point clouds on `topic` in the file's order, decoded, or why one could not be (the
    /// others still come).
    pub fn clouds<'a>(&'a self, topic: &'a str, limits: &'a ReadLimits) -> Result<Messages<'a>> {
        let topics = self.topics()?;
        let Some(t) = topics.iter().find(|t| t.name == topic) else {
            bail!("{}: no topic `{topic}` (topics: {})", self.path.display(), topics.iter().map(|t| format!("{} [{}]", t.name, t.schema)).collect::<Vec<_>>().join(", "));
        };
        let readable = (t.schema == POINTCLOUD2 && t.encoding == "cdr") || (t.schema == POINTCLOUD2_ROS1 && t.encoding == "ros1");
        if !readable {
            bail!("{}: topic `{topic}` holds {} in {} encoding; this reads {POINTCLOUD2} in cdr and {POINTCLOUD2_ROS1} in ros1", self.path.display(), t.schema, t.encoding);
        }
        let path = &self.path;
        let bad = move |index: usize, e: data_jrdb::ErrorKind| anyhow!("{}: message {index} on {topic}: {e}", path.display());
        Ok(match &self.storage {
            Storage::Mcap(map) => Box::new(self.mcap_stream(map)?.filter(move |m| m.as_ref().map_or(true, |m| m.channel.topic == topic)).enumerate().map(move |(i, m)| {
                let m = m.map_err(|e| anyhow!("{}: reading its messages: {e}", path.display()))?;
                // An MCAP converted from a ROS 1 bag keeps ROS 1's serialization.
                let decoded = if m.channel.message_encoding == "ros1" { decode_ros1(&m.data, limits) } else { decode_cdr(&m.data, limits) };
                let cloud = decoded.map_err(|e| bad(i, e))?;
                let channel = Arc::new(Channel {
                    topic: m.channel.topic.clone(),
                    schema: m.channel.schema.as_ref().map(|s| (s.name.clone(), s.encoding.clone(), s.data.to_vec())),
                    message_encoding: m.channel.message_encoding.clone(),
                });
                Ok(CloudMessage { cloud, log_time: m.log_time, publish_time: m.publish_time, channel, data: m.data })
            })),
            Storage::Db3(db) => {
                let channel = Arc::new(Channel { topic: topic.into(), schema: Some((POINTCLOUD2.into(), "ros2msg".into(), POINTCLOUD2_ROS2MSG.as_bytes().to_vec())), message_encoding: "cdr".into() });
                let ids: Vec<(i64, i64)> = db
                    .prepare("SELECT m.id, m.timestamp FROM messages m JOIN topics t ON m.topic_id = t.id WHERE t.name = ?1 ORDER BY m.timestamp, m.id")
                    .and_then(|mut s| s.query_map([topic], |r| Ok((r.get(0)?, r.get(1)?)))?.collect())
                    .with_context(|| format!("{}: listing the messages on {topic}", path.display()))?;
                Box::new(ids.into_iter().enumerate().map(move |(i, (id, time))| {
                    let data: Vec<u8> = db.query_row("SELECT data FROM messages WHERE id = ?1", [id], |r| r.get(0)).with_context(|| format!("{}: reading message {i} on {topic}", path.display()))?;
                    if data.starts_with(&[0x28, 0xb5, 0x2f, 0xfd]) {
                        bail!("{}: message {i} on {topic} is zstd-compressed (rosbag2's per-message compression): decompress the bag first (`ros2 bag convert`, or rosbags-convert to MCAP)", path.display());
                    }
                    let cloud = decode_cdr(&data, limits).map_err(|e| bad(i, e))?;
                    Ok(CloudMessage { cloud, log_time: time as u64, publish_time: time as u64, channel: channel.clone(), data: Cow::Owned(data) })
                }))
            }
            Storage::Ros1(bag) => Box::new(Ros1Messages::new(bag, topic).enumerate().map(move |(i, m)| {
                let (channel, time, data) = m.map_err(|e| anyhow!("{}: reading its chunks: {e}", path.display()))?;
                let cloud = decode_ros1(&data, limits).map_err(|e| bad(i, e))?;
                Ok(CloudMessage { cloud, log_time: time, publish_time: time, channel, data: Cow::Owned(data) })
            })),
        })
    }
}

/// Checks that a ROS 1 bag's header points at an index inside the file, which the `rosbag` crate
/// slices without checking: a bag cut short (or never closed, whose index position is 0) is an
/// error naming the file, not a panic. The header record is the version line, then
/// `u32 length` + fields `u32 length, name=value` (`index_pos` a u64), then `u32 length` + padding.
fn check_ros1_index(path: &Path) -> Result<()> {
    use std::io::Read;
    let file = std::fs::File::open(path).with_context(|| format!("{}: opening the ROS 1 bag", path.display()))?;
    let len = file.metadata().map(|m| m.len()).unwrap_or(0);
    let mut head = Vec::new();
    file.take(1 << 16).read_to_end(&mut head).with_context(|| format!("{}: reading the ROS 1 bag", path.display()))?;
    let not_a_bag = || anyhow!("{}: not a ROS 1 bag this reads (no `#ROSBAG V2.0` header record)", path.display());
    let rest = head.strip_prefix(b"#ROSBAG V2.0\n").ok_or_else(not_a_bag)?;
    let u32_at = |b: &[u8], at: usize| b.get(at..at + 4).map(|v| u32::from_le_bytes(v.try_into().unwrap()) as usize);
    let header_len = u32_at(rest, 0).ok_or_else(not_a_bag)?;
    let header = rest.get(4..4 + header_len).ok_or_else(not_a_bag)?;
    let data_len = u32_at(rest, 4 + header_len).ok_or_else(not_a_bag)?;
    let start = (13 + 4 + header_len + 4 + data_len) as u64;
    let mut at = 0;
    let mut index_pos = None;
    while let Some(n) = u32_at(header, at) {
        let field = header.get(at + 4..at + 4 + n).ok_or_else(not_a_bag)?;
        if let Some(v) = field.strip_prefix(b"index_pos=") {
            index_pos = v.try_into().ok().map(u64::from_le_bytes);
        }
        at += 4 + n;
    }
    let index_pos = index_pos.ok_or_else(not_a_bag)?;
    if index_pos < start || index_pos > len {
        bail!("{}: its index is not in the file (at byte {index_pos} of {len}): a bag cut short or never closed; `rosbag reindex` rebuilds it", path.display());
    }
    Ok(())
}

/// A ROS 1 bag's messages on one topic in file order: one chunk decompressed at a time, its
/// messages on the topic copied out before the next is read.
struct Ros1Messages<'a> {
    chunks: rosbag::ChunkRecordsIterator<'a>,
    topic: &'a str,
    channels: BTreeMap<u32, Arc<Channel>>,
    pending: VecDeque<(Arc<Channel>, u64, Vec<u8>)>,
    failed: bool,
    error: Option<rosbag::Error>,
}

impl<'a> Ros1Messages<'a> {
    fn new(bag: &'a rosbag::RosBag, topic: &'a str) -> Self {
        let mut channels = BTreeMap::new();
        // The index's connection records (checked present by `check_ros1_index`); the chunks'
        // own copies are read too, for a bag whose index omits some.
        for r in bag.index_records().flatten() {
            if let rosbag::IndexRecord::Connection(c) = r {
                learn(&mut channels, &c, topic);
            }
        }
        Ros1Messages { chunks: bag.chunk_records(), topic, channels, pending: VecDeque::new(), failed: false, error: None }
    }
}

fn learn(channels: &mut BTreeMap<u32, Arc<Channel>>, c: &rosbag::record_types::Connection<'_>, topic: &str) {
    if c.storage_topic == topic && !channels.contains_key(&c.id) {
        let schema = Some((c.tp.to_string(), "ros1msg".to_string(), c.message_definition.as_bytes().to_vec()));
        channels.insert(c.id, Arc::new(Channel { topic: topic.to_string(), schema, message_encoding: "ros1".into() }));
    }
}

impl Iterator for Ros1Messages<'_> {
    type Item = std::result::Result<(Arc<Channel>, u64, Vec<u8>), rosbag::Error>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Some(Ok(m));
            }
            if let Some(e) = self.error.take() {
                return Some(Err(e));
            }
            if self.failed {
                return None;
            }
            let chunk = match self.chunks.next()? {
                Ok(rosbag::ChunkRecord::Chunk(chunk)) => chunk,
                Ok(_) => continue,
                Err(e) => {
                    self.failed = true;
                    return Some(Err(e));
                }
            };
            for m in chunk.messages() {
                match m {
                    Ok(rosbag::MessageRecord::Connection(c)) => learn(&mut self.channels, &c, self.topic),
                    Ok(rosbag::MessageRecord::MessageData(d)) => {
                        if let Some(ch) = self.channels.get(&d.conn_id) {
                            self.pending.push_back((ch.clone(), d.time, d.data.to_vec()));
                        }
                    }
                    Err(e) => {
                        // The messages read before the damage still come, then the error.
                        self.failed = true;
                        self.error = Some(e);
                        break;
                    }
                }
            }
        }
    }
}
