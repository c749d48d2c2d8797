//! People in point clouds the user has: files (PCD, KITTI `.bin`, nuScenes `.pcd.bin`, `.npy`), folders of them,
//! glob patterns and JRDB-format trees, through a run's [`RunDetector`]. Per frame it writes
//!
//! ```text
//! OUT/json/<name>.json     a FrameReport: the boxes (x, y, z centre, l, w, h, yaw, score) in the input's frame
//! OUT/kitti/<name>.txt     the same boxes as the official evaluator's KITTI-style lines
//! OUT/render/<name>.png    with --render: bird's-eye view in JRDB's base frame
//! ```
//!
//! `<name>` is a file's stem, a file's path under a folder given (without extension), or
//! `<sequence>/<frame>` for a tree's frames. A recording (`.mcap`, `.db3`, `.bag`, a ROS 2 bag folder; `--topic`) is one input whose
//! messages are frames: `<name>/<index>` (index from 0 in the file's order), and `OUT/<name>.jsonl`
//! holds one report per line with each message's stamp and frame id; `--mcap OUT.mcap` writes the
//! clouds and the people for Foxglove (`scene`). The service (`serve`)
//! answers the same [`FrameReport`].

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail, ensure};
use data_jrdb::split::Layout;
use data_jrdb::{Box3d, CloudFormat, DatasetConfig, FormatInfo, Dataset, Split, read_cloud};
use eval::jrdb::Detection;
use eval::kitti::{FileKind, KittiObject};
use indicatif::ProgressBar;
use serde::{Deserialize, Serialize};

use crate::detector::RunDetector;
use crate::recording::{Recording, bag_folder_files, is_recording};
use crate::scene::SceneWriter;
use data_jrdb::cloud::ReadLimits;
use crate::progress;
use crate::render::render_bev;
use crate::sensor_pose::{FrameSpec, Placement, SensorPose};
use crate::validate::FrameResult;

/// One box as `detect` writes it and `serve` answers it: the centre, the size (l along the
/// heading), the heading (radians, counter-clockwise from +x) and the score, in the input's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BoxRecord {
    /// Centre x (metres).
    pub x: f64,
    /// Centre y (metres).
    pub y: f64,
    /// Centre z (metres), the middle of the height.
    pub z: f64,
    /// Length, along the heading.
    pub l: f64,
    /// Width, across the heading.
    pub w: f64,
    /// Height.
    pub h: f64,
    /// Heading (radians).
    pub yaw: f64,
    /// Confidence in [0, 1].
    pub score: f64,
}

impl BoxRecord {
    /// The record of a box and its score.
    pub fn new(b: &Box3d, score: f64) -> Self {
        Self { x: b.cx, y: b.cy, z: b.cz, l: b.l, w: b.w, h: b.h, yaw: b.rot_z, score }
    }
}

/// One frame's people, as `detect` writes them to `json/<name>.json` and `serve` answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameReport {
    /// The file (or `tree/sequence/frame`) the points came from.
    pub source: String,
    /// `pcd`, `bin`, `npy` or `jrdb` (a tree's two LiDARs merged).
    pub format: String,
    /// Finite points read.
    pub points: usize,
    /// Points dropped for a non-finite coordinate.
    pub dropped_non_finite: usize,
    /// Finite points dropped for lying outside the run's working volume (`data.volume`, in the
    /// base frame): far and max-range returns.
    #[serde(default)]
    pub dropped_out_of_volume: usize,
    /// The input frame's pose in JRDB's base frame (`x=…,y=…,z=…,yaw=…` degrees).
    pub pose: String,
    /// How the pose was chosen: `given`, `ground: …` (found in the scan, `--transform auto`) or
    /// `no ground: …` (the given pose kept), or the tree's calibration.
    #[serde(default)]
    pub frame: String,
    /// Boxes scoring at least `score_threshold`, best first, in the input's frame.
    pub detections: Vec<BoxRecord>,
    /// The score threshold applied.
    pub score_threshold: f64,
    /// A recording's message: its header's stamp (seconds) and frame id, its index on the topic.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<MessageInfo>,
}

/// Where a frame of a recording came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MessageInfo {
    /// The topic.
    pub topic: String,
    /// Its index on the topic, from 0, in the file's order.
    pub index: usize,
    /// `header.stamp` in seconds.
    pub stamp: f64,
    /// `header.frame_id`.
    pub frame_id: String,
    /// The recording's log time of the message (nanoseconds).
    pub log_time_ns: u64,
}

/// A cloud's people in the base frame (for drawing) and in the input's frame (for writing).
#[derive(Debug, Clone, Default)]
pub struct Found {
    /// The points, in the base frame.
    pub base_points: Vec<[f32; 3]>,
    /// The detections in the base frame, best first.
    pub base: Vec<Detection>,
    /// The same detections in the input's frame.
    pub input: Vec<Detection>,
    /// Points dropped for lying outside the run's working volume.
    pub dropped_out_of_volume: usize,
}

/// Moves `points` into the base frame with `pose`, drops those outside the run's working volume,
/// detects, keeps the boxes scoring at least `score_threshold` (after the run's own
/// post-processing, so the boxes are those `infer` scores) and moves them back.
pub fn find_people(detector: &RunDetector, points: &[[f32; 3]], pose: &SensorPose, score_threshold: f64) -> Found {
    let mut base_points: Vec<[f32; 3]> = if pose.is_identity() { points.to_vec() } else { points.iter().map(|&p| pose.to_base(p)).collect() };
    let dropped_out_of_volume = detector.config().data.volume.crop(&mut base_points);
    if base_points.is_empty() {
        return Found { dropped_out_of_volume, ..Found::default() };
    }
    let found = detector.detect(&base_points);
    let base: Vec<Detection> =
        found.boxes.iter().zip(&found.scores).map(|(b, &s)| Detection { bbox: *b, score: s as f64 }).filter(|d| d.score >= score_threshold).collect();
    let input = base.iter().map(|d| Detection { bbox: pose.box_to_input(&d.bbox), score: d.score }).collect();
    Found { base_points, base, input, dropped_out_of_volume }
}

/// Places `points` (in the sensor's own frame) as `frame` says, by default from the ground in
/// them, then [`find_people`]: the library's way to detect in a cloud straight from a driver.
pub fn find_people_placed(detector: &RunDetector, points: &[[f32; 3]], frame: &FrameSpec, score_threshold: f64) -> (Placement, Found) {
    let placement = frame.place(points);
    let found = find_people(detector, points, &placement.pose, score_threshold);
    (placement, found)
}

/// What a caught panic said, for a message naming the input it happened on.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

/// The short name of a cloud format, as reports give it.
pub fn format_name(f: CloudFormat) -> &'static str {
    f.info().name
}

/// Where one input frame's points come from.
#[derive(Debug, Clone)]
pub enum Source {
    /// A cloud file.
    File(PathBuf),
    /// Frame `index` of a JRDB-format tree (both LiDARs merged by its calibration).
    Tree(Arc<Dataset>, usize),
    /// A recording (MCAP): every point cloud on `DetectOptions::topic`.
    Recording(PathBuf),
}

/// One frame to detect in, and the name its outputs get.
#[derive(Debug, Clone)]
pub struct Input {
    /// The points' origin.
    pub source: Source,
    /// Output name: `/`-separated, no extension.
    pub name: String,
}

impl Input {
    fn describe(&self) -> String {
        match &self.source {
            Source::File(p) | Source::Recording(p) => p.display().to_string(),
            Source::Tree(ds, i) => format!("{}/{}/{}", ds.root.display(), ds.frames[*i].sequence, ds.frames[*i].name),
        }
    }
}

/// The frames that `paths` name: files, folders (searched recursively for `.pcd`, `.bin` and
/// `.npy`), JRDB-format trees (a folder with `pointclouds/`, or its `train_dataset*/`) and glob
/// patterns of those (for shells that do not expand them). Two inputs that would write the same
/// output name are an error.
pub fn collect_inputs(paths: &[PathBuf]) -> Result<Vec<Input>> {
    ensure!(!paths.is_empty(), "no input: give point-cloud files, folders, glob patterns or a JRDB-format tree");
    let mut inputs = Vec::new();
    for p in paths {
        let text = p.to_string_lossy();
        if !p.exists() && text.contains(['*', '?', '[']) {
            let matches = glob::glob(&text).with_context(|| format!("{text}: not a valid glob pattern"))?;
            let mut n = 0;
            for m in matches {
                let m = m.with_context(|| format!("{text}: reading a match"))?;
                add_path(&m, &mut inputs)?;
                n += 1;
            }
            ensure!(n > 0, "{text}: the pattern matches nothing");
        } else {
            add_path(p, &mut inputs)?;
        }
    }
    let mut names: Vec<(&str, usize)> = inputs.iter().enumerate().map(|(i, x)| (x.name.as_str(), i)).collect();
    names.sort();
    if let Some(w) = names.windows(2).find(|w| w[0].0 == w[1].0) {
        bail!(
            "{} and {} would both write outputs named `{}`; run them into different --out folders",
            inputs[w[0].1].describe(),
            inputs[w[1].1].describe(),
            w[0].0
        );
    }
    Ok(inputs)
}

fn add_path(p: &Path, inputs: &mut Vec<Input>) -> Result<()> {
    let meta = std::fs::metadata(p).with_context(|| format!("{}: no such file or folder", p.display()))?;
    if !meta.is_dir() {
        let name = p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| p.display().to_string());
        let source = if is_recording(p) { Source::Recording(p.to_path_buf()) } else { Source::File(p.to_path_buf()) };
        inputs.push(Input { source, name });
        return Ok(());
    }
    let bag = bag_folder_files(p)?;
    if !bag.is_empty() {
        // A ROS 2 bag folder: its storage files, each a recording named after the folder.
        let folder = p.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "bag".into());
        let one = bag.len() == 1;
        for f in bag {
            let name = if one { folder.clone() } else { format!("{folder}/{}", f.file_stem().unwrap_or_default().to_string_lossy()) };
            inputs.push(Input { source: Source::Recording(f), name });
        }
        return Ok(());
    }
    if Layout::resolve(p).is_ok() {
        let cfg = DatasetConfig { split: Split::TrainVal, require_labels: false, ..Default::default() };
        let ds = Arc::new(Dataset::open(p, &cfg).with_context(|| format!("{}: reading the JRDB-format tree", p.display()))?);
        ensure!(!ds.is_empty(), "{}: the JRDB-format tree has no frames", p.display());
        for (i, f) in ds.frames.iter().enumerate() {
            inputs.push(Input { source: Source::Tree(ds.clone(), i), name: format!("{}/{}", f.sequence, f.name) });
        }
        return Ok(());
    }
    let mut files = Vec::new();
    walk(p, &mut files)?;
    files.sort();
    ensure!(!files.is_empty(), "{}: no {} file in this folder or below", p.display(), FormatInfo::extensions());
    for f in files {
        let rel = f.strip_prefix(p).unwrap_or(&f).with_extension("");
        let name = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect::<Vec<_>>().join("/");
        inputs.push(Input { source: Source::File(f), name });
    }
    Ok(())
}

fn walk(dir: &Path, files: &mut Vec<PathBuf>) -> Result<()> {
    for entry in std::fs::read_dir(dir).with_context(|| format!("{}: listing the folder", dir.display()))? {
        let entry = entry.with_context(|| format!("{}: listing the folder", dir.display()))?;
        let path = entry.path();
        if entry.file_type()?.is_dir() {
            walk(&path, files)?;
        } else if CloudFormat::from_extension(&path).is_some() {
            files.push(path);
        }
    }
    Ok(())
}

/// What `detect` does besides finding people.
#[derive(Debug, Clone)]
pub struct DetectOptions {
    /// The input files' pose in the base frame, or the ground to find in each (trees are merged
    /// by their own calibration).
    pub frame: FrameSpec,
    /// Boxes scoring below this are not written.
    pub score_threshold: f64,
    /// The output folder.
    pub out: PathBuf,
    /// Draw each frame.
    pub render: bool,
    /// A progress bar for more than one frame.
    pub verbose: bool,
    /// The topic of the point clouds in a recording.
    pub topic: Option<String>,
    /// Also write the recordings' clouds and the people found as an MCAP Foxglove opens.
    pub mcap: Option<PathBuf>,
}

/// What `detect` did.
#[derive(Debug, Clone, Default)]
pub struct DetectSummary {
    /// Frames detected in and written.
    pub frames: usize,
    /// Boxes written.
    pub boxes: usize,
    /// Inputs that could not be read or written, with the reason.
    pub failed: Vec<(String, String)>,
    /// Wall time of the whole command's loop (reading, detecting, writing).
    pub seconds: f64,
    /// Time spent in the detector alone.
    pub detect_seconds: f64,
}

/// Detects in every input and writes its outputs under `opts.out`; a frame that cannot be read
/// is reported in the summary and the others go on.
pub fn detect(detector: &RunDetector, inputs: &[Input], opts: &DetectOptions) -> Result<DetectSummary> {
    std::fs::create_dir_all(&opts.out).with_context(|| format!("{}: creating the output folder", opts.out.display()))?;
    // A recording counts its messages on the topic where its summary says them.
    let mut frames = 0u64;
    let mut recordings = Vec::new();
    for input in inputs {
        match &input.source {
            Source::Recording(p) => {
                let Some(topic) = opts.topic.as_deref() else {
                    let topics = Recording::open(p)?.topics()?;
                    bail!("{}: a recording: give --topic (its topics: {})", p.display(), topics.iter().map(|t| format!("{} [{}]", t.name, t.schema)).collect::<Vec<_>>().join(", "));
                };
                let r = Recording::open(p)?;
                frames += r.topics()?.iter().find(|t| t.name == topic).and_then(|t| t.messages).unwrap_or(0);
                recordings.push(r);
            }
            _ => frames += 1,
        }
    }
    if let Some(out) = &opts.mcap {
        ensure!(inputs.iter().all(|i| matches!(i.source, Source::Recording(_))), "--mcap {}: every input must be a recording (.mcap, .db3 or .bag)", out.display());
    }
    let mut scene = opts.mcap.as_deref().map(SceneWriter::create).transpose()?;
    let pb = if opts.verbose && frames > 1 { progress::bar(frames, "detect") } else { ProgressBar::hidden() };
    let mut summary = DetectSummary::default();
    let start = Instant::now();
    let mut recordings = recordings.into_iter();
    for input in inputs {
        if let Source::Recording(p) = &input.source {
            let r = recordings.next().expect("one opened per recording input");
            // A panic in a storage crate fails this recording alone.
            let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| detect_recording(detector, &r, input, opts, &pb, &mut summary, scene.as_mut())))
                .unwrap_or_else(|payload| Err(anyhow::anyhow!("reading the recording failed: {}", panic_message(&*payload))));
            if let Err(e) = outcome {
                pb.suspend(|| eprintln!("skipped the rest of {}: {e:#}", p.display()));
                summary.failed.push((p.display().to_string(), format!("{e:#}")));
            }
            continue;
        }
        // A panic on one input (inside the model, say) fails that input alone.
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| detect_one(detector, input, opts)))
            .unwrap_or_else(|payload| Err(anyhow::anyhow!("the detector failed on this cloud: {}", panic_message(&*payload))));
        record(&mut summary, &pb, input.describe(), outcome.map(|(r, secs)| (r.detections.len(), secs)));
        pb.inc(1);
    }
    pb.finish_and_clear();
    if let Some(scene) = scene {
        scene.finish()?;
    }
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

fn record(summary: &mut DetectSummary, pb: &ProgressBar, what: String, outcome: Result<(usize, f64)>) {
    match outcome {
        Ok((n, secs)) => {
            summary.frames += 1;
            summary.boxes += n;
            summary.detect_seconds += secs;
        }
        Err(e) => {
            let why = format!("{e:#}");
            // Reader errors name the file themselves.
            let line = if why.starts_with(&what) { why.clone() } else { format!("{what}: {why}") };
            pb.suspend(|| eprintln!("skipped {line}"));
            summary.failed.push((what, why));
        }
    }
}

/// Every point cloud of a recording's topic: a frame each, written as `<name>/<index>` and a line
/// of `OUT/<name>.jsonl`; a message that cannot be decoded is reported and the next one read.
fn detect_recording(detector: &RunDetector, r: &Recording, input: &Input, opts: &DetectOptions, pb: &ProgressBar, summary: &mut DetectSummary, mut scene: Option<&mut SceneWriter>) -> Result<()> {
    let topic = opts.topic.as_deref().context("--topic")?;
    let limits = ReadLimits::NONE;
    let jsonl_path = opts.out.join(format!("{}.jsonl", input.name));
    if let Some(dir) = jsonl_path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: creating the folder", dir.display()))?;
    }
    let mut jsonl = std::io::BufWriter::new(std::fs::File::create(&jsonl_path).with_context(|| format!("{}: creating", jsonl_path.display()))?);
    for (index, m) in r.clouds(topic, &limits)?.enumerate() {
        let what = format!("{} message {index} on {topic}", input.describe());
        let outcome = m.and_then(|m| {
            let cloud = m.cloud;
            let frame = Input { source: input.source.clone(), name: format!("{}/{index:06}", input.name) };
            let message = MessageInfo { topic: topic.to_string(), index, stamp: cloud.stamp.seconds(), frame_id: cloud.frame_id.clone(), log_time_ns: m.log_time };
            let placement = opts.frame.place(&cloud.points);
            let (stamp, frame_id) = (cloud.stamp, cloud.frame_id.clone());
            let (report, secs) = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                write_frame(detector, &frame, opts, cloud.points, cloud.dropped_non_finite, "mcap", placement, Some(message))
            }))
            .unwrap_or_else(|payload| Err(anyhow::anyhow!("the detector failed on this cloud: {}", panic_message(&*payload))))?;
            if let Some(scene) = scene.as_deref_mut() {
                scene.copy(&m.channel, m.log_time, m.publish_time, &m.data)?;
                scene.people(m.log_time, stamp, &frame_id, &report.detections)?;
            }
            Ok((report, secs))
        });
        let outcome = outcome.and_then(|(report, secs)| {
            use std::io::Write;
            writeln!(jsonl, "{}", serde_json::to_string(&report)?).with_context(|| format!("{}: writing", jsonl_path.display()))?;
            Ok((report.detections.len(), secs))
        });
        record(summary, pb, what, outcome);
        pb.inc(1);
    }
    use std::io::Write;
    jsonl.flush().with_context(|| format!("{}: writing", jsonl_path.display()))?;
    Ok(())
}

fn detect_one(detector: &RunDetector, input: &Input, opts: &DetectOptions) -> Result<(FrameReport, f64)> {
    let (points, dropped, format, placement) = match &input.source {
        Source::File(p) => {
            let c = read_cloud(p)?;
            let placement = opts.frame.place(&c.points);
            (c.points, c.dropped_non_finite, format_name(c.format), placement)
        }
        Source::Tree(ds, i) => {
            let f = ds.load(*i)?;
            (f.points, f.dropped_non_finite, "jrdb", Placement { pose: SensorPose::default(), how: "the tree's calibration".into() })
        }
        Source::Recording(_) => unreachable!("recordings are read message by message"),
    };
    write_frame(detector, input, opts, points, dropped, format, placement, None)
}

/// Finds the people of one frame and writes its outputs; returns its report and the detector's
/// time.
#[allow(clippy::too_many_arguments)]
fn write_frame(detector: &RunDetector, input: &Input, opts: &DetectOptions, points: Vec<[f32; 3]>, dropped: usize, format: &str, placement: Placement, message: Option<MessageInfo>) -> Result<(FrameReport, f64)> {
    let pose = placement.pose;
    let t = Instant::now();
    let found = find_people(detector, &points, &pose, opts.score_threshold);
    let secs = t.elapsed().as_secs_f64();
    let report = FrameReport {
        source: input.describe(),
        format: format.into(),
        points: points.len(),
        dropped_non_finite: dropped,
        dropped_out_of_volume: found.dropped_out_of_volume,
        pose: pose.to_string(),
        frame: placement.how,
        detections: found.input.iter().map(|d| BoxRecord::new(&d.bbox, d.score)).collect(),
        score_threshold: opts.score_threshold,
        message,
    };
    let json = opts.out.join("json").join(format!("{}.json", input.name));
    write_file(&json, serde_json::to_string_pretty(&report)?.as_bytes())?;
    let kitti: Vec<KittiObject> = found.input.iter().map(|d| KittiObject::from_box3d(&d.bbox, -1, d.score)).collect();
    let txt = opts.out.join("kitti").join(format!("{}.txt", input.name));
    if let Some(dir) = txt.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: creating the folder", dir.display()))?;
    }
    eval::kitti::write_file(&txt, &kitti, FileKind::Detections)?;
    if opts.render {
        let png = opts.out.join("render").join(format!("{}.png", input.name));
        if let Some(dir) = png.parent() {
            std::fs::create_dir_all(dir).with_context(|| format!("{}: creating the folder", dir.display()))?;
        }
        let frame = FrameResult { sequence: String::new(), name: input.name.clone(), gt: Vec::new(), num_points: Vec::new(), ignored: Vec::new(), detections: found.base };
        render_bev(&found.base_points, &frame, &png, detector.config().eval.max_range.unwrap_or(25.0))?;
    }
    Ok((report, secs))
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("{}: creating the folder", dir.display()))?;
    }
    std::fs::write(path, bytes).with_context(|| format!("{}: writing", path.display()))
}
